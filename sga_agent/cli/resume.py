"""``sga-agent resume``: continue a search that was stopped or killed."""

from __future__ import annotations

from pathlib import Path

import click

from sga_agent import registry
from sga_agent.cli import main
from sga_agent.cli.options import Duration, check_device_here
from sga_agent.cli.search import check_executor, execute, prepare
from sga_agent.config import UNTIL_BUDGET, ConfigError, SearchConfig
from sga_agent.events import RunResumed
from sga_agent.proposers.base import Proposer, ProposerError
from sga_agent.proposers.litellm_backbone import LiteLLMProposer
from sga_agent.run_store import RunFolderFull, RunLocked, RunStore, RunStoreError
from sga_agent.search import slots_of
from sga_agent.task.device import DEVICES


@main.command()
@click.argument("run_dir", type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option(
    "--ray-address",
    metavar="HOST:PORT",
    help="Continue a run of --executor ray on this Ray cluster instead of its own.",
)
@click.option(
    "--time-budget",
    "max_seconds",
    type=Duration(),
    help="A new wall-time budget for the whole run, its earlier sessions included, e.g. 20m "
    "(recorded as the run's): to evaluate what a time budget stopped, or to search longer.",
)
@click.option(
    "--device",
    type=click.Choice(DEVICES),
    help="Continue on this device instead of the run's own (a run of --device cuda on a "
    "machine without a GPU, say).",
)
@click.option("--json", "as_json", is_flag=True, help="Print only the summary as JSON.")
def resume(
    run_dir: Path,
    ray_address: str | None,
    max_seconds: float | None,
    device: str | None,
    as_json: bool,
) -> None:
    """Continue the search recorded in RUN_DIR.

    Recorded model answers are not asked again and finished evaluations are not re-run; the
    search goes on from where it stopped with the run's own settings (and executor). A run is
    written by one process at a time: resuming a run that a search or another resume is
    writing stops at once, naming that process.
    """
    try:
        store = RunStore.open(run_dir)
        name = store.config_record()["task"]
    except RunStoreError as error:
        raise click.BadParameter(str(error), param_hint="'RUN_DIR'") from error
    try:
        store.lock()  # before anything is written: two resumes never interleave
    except RunLocked as error:
        raise click.ClickException(str(error)) from error
    try:
        loaded = registry.load_task(name)  # this process's one load of its task
    except registry.UnknownTaskError as error:
        raise click.ClickException(f"the run's task is not installed here: {error}") from error
    try:
        config = store.config(loaded.options_type)
    except ConfigError as error:
        raise click.BadParameter(str(error), param_hint="'RUN_DIR'") from error
    try:
        if ray_address is not None:
            config = config.replace(ray_address=ray_address)
        if max_seconds is not None:
            config = config.replace(max_seconds=max_seconds)
        if device is not None:
            config = config.replace(device=device)
    except ConfigError as error:
        raise click.UsageError(str(error)) from error
    check_executor(config)
    check_device_here(config.sandbox.device)
    task, proposer = prepare(config, loaded)
    if answers_wanted(config, store):
        check_model_answers(proposer, store)
    recorded = store.recorded()
    if recorded.finished and not recorded.stopped:
        click.echo("this run had finished: nothing is left to evaluate; its result:", err=True)
    elif recorded.stopped and max_seconds is None:
        click.echo(f"this run was stopped by its budget ({recorded.stopped}); a larger "
                   "--time-budget lets a time-stopped run go on", err=True)  # fmt: skip
    try:
        if max_seconds is not None or device is not None:
            store.update_config(config)
        store.append(RunResumed(ray_address, max_seconds))
        execute(config, store, as_json, proposer, task)
    except RunFolderFull as error:  # the disk is full: the message says what to do
        raise click.ClickException(str(error)) from error


def answers_wanted(config: SearchConfig, store: RunStore) -> bool:
    """Whether the rest of the run asks the proposer for answers it has not recorded."""
    if config.loop.iterations == UNTIL_BUDGET:
        return True
    recorded = store.recorded().proposals
    return any(
        candidate not in recorded
        for iteration in range(1, config.loop.iterations + 1)
        for candidate, _ in slots_of(config.loop, iteration)
    )


def check_model_answers(proposer: Proposer, store: RunStore) -> None:
    """A model that does not answer yet stops the resume at once; the run stays as it was."""
    if isinstance(proposer, LiteLLMProposer):
        try:
            proposer.check_reachable()
        except ProposerError as error:
            store.unlock()
            raise click.ClickException(
                f"{error}\nthe run is unchanged: `sga-agent resume {store.path}` again once the "
                "model answers"
            ) from error
