"""``sga-agent search``: run the bilevel search on a task."""

from __future__ import annotations

import shutil
from pathlib import Path

import click
from rich.console import Console

from sga_agent import registry, runner
from sga_agent.cli import main
from sga_agent.cli.clock import command_started
from sga_agent.cli.interrupt import INTERRUPTED, interrupts_stop_the_search
from sga_agent.cli.options import (
    Duration,
    Price,
    check_device_here,
    registered_task,
    task_options,
    typed_task_options,
)
from sga_agent.cli.progress import SearchProgress, print_result
from sga_agent.config import (
    EXECUTORS,
    FIDELITIES,
    PRESETS,
    ConfigError,
    SearchConfig,
    default,
    quick_screening,
)
from sga_agent.proposers.base import Proposer, ProposerError
from sga_agent.proposers.litellm_backbone import LiteLLMProposer
from sga_agent.ray_executor import RAY_INSTALL, RayUnavailableError, import_ray
from sga_agent.run_store import RunFolderFull, RunStore, RunStoreError
from sga_agent.task import TaskBase, as_task, configured
from sga_agent.task.device import DEVICES
from sga_agent.wording import counted


class SearchCommand(click.Command):
    """``search``, whose usage error for ``--resume`` names the command that resumes (click
    alone would suggest the closest option, ``--preset``)."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        given = list(args)  # click consumes ``args``
        try:
            return super().parse_args(ctx, args)
        except click.NoSuchOption as error:
            if error.option_name != "--resume":
                raise
            raise click.UsageError(
                f"search has no --resume option: `sga-agent resume {resumed_folder(given)}` "
                "continues a stopped run", ctx
            ) from None  # fmt: skip


def resumed_folder(args: list[str]) -> str:
    """The folder given with ``--resume`` (``--resume DIR`` or ``--resume=DIR``), else
    ``RUN_DIR``."""
    for i, arg in enumerate(args):
        name, sep, value = arg.partition("=")
        if name == "--resume":
            if sep:
                return value or "RUN_DIR"
            follows = args[i + 1] if i + 1 < len(args) else ""
            return follows if follows and not follows.startswith("-") else "RUN_DIR"
    return "RUN_DIR"


def from_preset(name: str) -> str:
    """How a preset-dependent default reads in the help: "5 (sga), 4 (quick)"."""
    return f"{PRESETS['sga'][name]} (sga), {PRESETS['quick'][name]} (quick)"


# fmt: off
@main.command(cls=SearchCommand)
@click.option("--task", "task", required=True, callback=registered_task, metavar="NAME",
              help="Registered task (see `sga-agent tasks`).")
@click.option("--model", metavar="PROVIDER/MODEL", envvar="SGA_MODEL",
              help="litellm model string, e.g. openai/gpt-4o, anthropic/claude-3-5-sonnet-"
              "20240620, hosted_vllm/NAME (the key comes from the provider's environment "
              "variable: OPENAI_API_KEY, ANTHROPIC_API_KEY, ...), or builtin (the task's "
              "LLM-free proposer: builtin:gp for laws, builtin:ga for molecules).",
              show_default="builtin")
@click.option("--api-base", metavar="URL", help="Base URL of an OpenAI-compatible server.")
@click.option("--replay", type=click.Path(exists=True, file_okay=False, path_type=Path),
              help="Re-run a recorded search: its model answers, no model call.")
@click.option("--preset", type=click.Choice(list(PRESETS)),
              show_default="sga with a model, quick without",
              help="Settings of a column of the paper's Table 1, or quick (overridden by the "
              "options).")
@click.option("--iterations", type=click.IntRange(min=1),
              show_default=from_preset("iterations") + "; with --time-budget, until the budget",
              help="Outer iterations.")
@click.option("--top-k", type=click.IntRange(min=1), show_default=from_preset("top_k"),
              help="Solutions shown per prompt (K).")
@click.option("--exploit", type=click.IntRange(min=0), show_default=from_preset("exploit"),
              help="Offspring per iteration at T_l.")
@click.option("--explore", type=click.IntRange(min=0), show_default=from_preset("explore"),
              help="Offspring per iteration at T_h.")
@click.option("--t-exploit", "exploit_temperature", type=click.FloatRange(0, 2),
              show_default=str(default("exploit_temperature")), help="Exploit temperature T_l.")
@click.option("--t-explore", "explore_temperature", type=click.FloatRange(0, 2),
              show_default=str(default("explore_temperature")), help="Explore temperature T_h.")
@click.option("--fidelity", type=click.Choice(FIDELITIES),
              show_default="multi in quick on a task that screens cheaply (the constitutive "
              "tasks) without --time-budget, else full",
              help="full: every candidate gets the full fit; multi: each is screened by a "
              "cheaper fit and the best --promote share of each iteration's screens gets the "
              "full fit (only full fits are ranked and shown).")
@click.option("--screen-fidelity", type=click.FloatRange(0, 1, min_open=True, max_open=True),
              show_default=f"{default('screen_fidelity')}; in quick without --time-budget: "
              "with an opening, the task's opening screen (0.2 on elastic), else 0.2",
              help="The screen's share of the full fit's work (--fidelity multi).")
@click.option("--promote", type=click.FloatRange(0, 1, min_open=True),
              show_default=f"{default('promote')}; 0.1 in quick with an opening",
              help="Share of an iteration's valid screens promoted to the full fit "
              "(--fidelity multi; rounded up, at least one), of those below the bar of "
              "--promote-rank.")
@click.option("--promote-rank", type=click.IntRange(min=1),
              show_default=f"{default('promote_rank')}; --top-k in quick without --time-budget",
              help="The bar of promotion (--fidelity multi): a screen is promoted only "
              "below the screen of this rank among the earlier iterations' valid ones.")
@click.option("--parsimony", type=click.FloatRange(0, 1, max_open=True),
              show_default="0.01 in quick, 0 in the other presets",
              help="Share of the loss a fitted parameter must win: solutions rank by loss * "
              "(1 + parsimony) ** parameters (0: by loss alone).")
@click.option("--opening", type=click.IntRange(min=0),
              show_default="in quick with the built-in proposer on a task that screens "
              "cheaply, without --time-budget, --iterations, --exploit or --explore: the "
              "task's (40; 20 on elastic); else 0",
              help="Explore answers of the first iteration, when more than --explore: a wide "
              "first look (the built-in proposer of laws tries its most likely forms).")
@click.option("--no-bilevel", "no_bilevel", is_flag=True, default=None,
              help="Do not fit parameters: evaluate the proposed defaults.")
@click.option("--epochs", type=click.IntRange(min=0), show_default="the task's; 5 in quick",
              help="Inner-optimization epochs.")
@click.option("--lr", "learning_rate", type=click.FloatRange(min=0, min_open=True),
              show_default="the task's", help="Inner-optimization learning rate.")
@click.option("--option", "task_options", multiple=True, callback=task_options,
              metavar="KEY=VALUE", help="Task option, repeatable (e.g. steps=200); unknown keys "
              "and bad values are usage errors.")
@click.option("--workers", type=click.IntRange(min=1), default=default("workers"),
              show_default="CPU cores", help="Candidates evaluated at once (one process each).")
@click.option("--timeout", "timeout_s", type=click.FloatRange(min=1), default=default("timeout_s"),
              show_default=True, help="Wall-clock limit of one evaluation (s).")
@click.option("--memory-mb", type=click.IntRange(min=64), default=default("memory_mb"),
              show_default=True, help="Memory limit of one evaluation (MiB).")
@click.option("--device", type=click.Choice(DEVICES), default=default("device"),
              show_default=True, help="Where the fits compute: Taichi's kernels on this CPU or "
              "on a CUDA GPU (checked before anything starts).")
@click.option("--executor", type=click.Choice(EXECUTORS), default=default("executor"),
              show_default=True,
              help="Where candidates are evaluated: this machine's pool of sandboxed worker "
              "processes, or a Ray cluster (each evaluation a Ray task running the same "
              f"sandboxed worker on a node; needs `{RAY_INSTALL}`).")
@click.option("--ray-address", metavar="HOST:PORT",
              show_default="a private local Ray instance of --workers CPUs",
              help="Head node of the Ray cluster (the port of `ray start --head`), or auto "
              "(RAY_ADDRESS, else a cluster started on this machine).")
@click.option("--ray-cpus", "ray_cpus_per_task", type=click.FloatRange(min=0, min_open=True),
              show_default=str(default("ray_cpus_per_task")),
              help="CPUs each evaluation reserves on its Ray node.")
@click.option("--ray-memory-mb", type=click.IntRange(min=1), show_default="none",
              help="Memory each evaluation reserves on its Ray node, MiB.")
@click.option("--request-timeout", "request_timeout_s", type=click.FloatRange(min=0, min_open=True),
              show_default=str(default("request_timeout_s")),
              help="Seconds one request to the model may take before it is retried.")
@click.option("--retries", type=click.IntRange(min=0), show_default=str(default("retries")),
              help="Further attempts after a model request timed out, was rate-limited or "
              "failed on the server; then the search stops (resumable).")
@click.option("--prompt-tokens", type=click.IntRange(min=500),
              show_default=str(default("prompt_tokens")),
              help="Most tokens of a prompt (litellm's counter for the model): earlier "
              "solutions' feedback is shortened, the worst first, to fit.")
@click.option("--price", type=Price(), metavar="IN,OUT",
              help="USD per million input and output tokens, e.g. 2.5,10: for a model "
              "litellm cannot price (then needed by --max-usd), or to override its price.")
@click.option("--max-usd", type=click.FloatRange(min=0, min_open=True), help="Budget in USD.")
@click.option("--max-tokens", type=click.IntRange(min=1), help="Budget in tokens.")
@click.option("--max-evaluations", type=click.IntRange(min=1), help="Budget in evaluations.")
@click.option("--time-budget", "max_seconds", type=Duration(),
              help="Budget in wall time from the program's start, e.g. 15m or 1h30m (a "
              "resume counts the time the run already took). The evaluations running 3 % "
              "before it (30 s at most) are stopped, recorded as stopped and left for a "
              "resume; the best found is assessed in that time. Without --iterations the "
              "search iterates until it.")
@click.option("--seed", type=int, default=default("seed"), show_default=True,
              help="Seed of the run.")
@click.option("--out-dir", "out", type=click.Path(file_okay=False, path_type=Path),
              default=Path("runs"), show_default=True,
              help="Folder in which the run folder (TASK-DATE-TIME) is made.")
@click.option("--json", "as_json", is_flag=True, help="Print only the summary as JSON.")
# fmt: on
def search(
    model, api_base, replay, preset, no_bilevel, out, as_json, task, task_options, **settings
) -> None:
    """Search TASK's solutions with a model and differentiable simulation.

    Each iteration shows the model the top-K solutions with their feedback, asks for
    --exploit answers at T_l and --explore at T_h, evaluates them in sandboxed workers and
    keeps the best. The run folder records everything; `sga-agent resume RUN_DIR` continues
    a run that was stopped.
    """  # fmt: skip
    if model and replay:
        raise click.UsageError("give either --model or --replay, not both")
    builtin = not model and not replay
    if builtin:
        model = runner.BUILTIN
    proposer = model if model else f"{runner.REPLAY_PREFIX}{replay.resolve()}"
    loaded = registry.load_task(task)  # this process's one load of its task
    options = typed_task_options(loaded, task_options, proposer)
    if preset is None:
        preset = "quick" if proposer.startswith(runner.BUILTIN) else "sga"
    described = as_task(loaded)
    opening = (described.opening_answers, described.opening_screen) if builtin else None
    settings |= quick_screening(preset, settings, described.screens_cheaply, opening)
    try:
        config = SearchConfig.from_preset(
            preset, task=task, proposer=proposer, api_base=api_base, task_options=options,
            bilevel=False if no_bilevel else None, **settings,
        )  # fmt: skip
        if replay:
            runner.replayed_answers(config)  # fail early on a bad folder
    except (ConfigError, RunStoreError) as error:
        raise click.UsageError(str(error)) from error
    check_executor(config)
    check_device_here(config.sandbox.device)
    check_pricing(config)
    set_up, chosen = prepare(config, loaded)
    check_reachable(chosen)
    if builtin:  # after every usage error
        click.echo(
            "no --model: the task's built-in LLM-free proposer searches (preset quick); "
            "--model openai/gpt-4o (with OPENAI_API_KEY set) searches with an LLM",
            err=True,
        )
    store = RunStore.create(out, config, {"proposer": proposer})
    execute(config, store, as_json, chosen, set_up, new_run=True)


def check_executor(config: SearchConfig) -> None:
    """The ray executor without Ray installed is a usage error, before anything starts."""
    if config.executor.kind == "ray":
        try:
            import_ray()
        except RayUnavailableError as error:
            raise click.UsageError(str(error)) from error


def check_pricing(config: SearchConfig) -> None:
    """A money budget for a model litellm cannot price, with no ``--price``, is a usage error:
    its cost would count as 0 and the budget would never stop the run."""
    if config.budgets.max_usd is None or config.model.price is not None:
        return
    if runner.is_builtin(config.proposer) or config.proposer.startswith(runner.REPLAY_PREFIX):
        return
    from sga_agent.proposers.litellm_backbone import is_priced

    if not is_priced(config.proposer):
        raise click.UsageError(
            f"--max-usd needs a price, and litellm's price map has none for "
            f"{config.proposer}: give one with --price IN,OUT (USD per million input and "
            "output tokens, e.g. --price 2.5,10)"
        )


def check_reachable(proposer: Proposer) -> None:
    """Ask a model for one word before anything starts, so that a provider that is down,
    refuses the key or does not know the model stops the command at once (no run folder)."""
    if isinstance(proposer, LiteLLMProposer):
        try:
            proposer.check_reachable()
        except ProposerError as error:
            raise click.ClickException(f"{error}\nno run was started") from error


def prepare(config: SearchConfig, loaded: TaskBase) -> tuple[TaskBase, Proposer]:
    """The run's task (``loaded``) set up for its options, and its proposer; a bad choice of
    proposer is a usage error, a missing API key an error."""
    try:
        task = configured(loaded, config.task_options)
        proposer = runner.make_proposer(config, task)
    except ValueError as error:  # unknown built-in, malformed model string
        raise click.UsageError(str(error)) from error
    if isinstance(proposer, LiteLLMProposer):
        try:
            proposer.check_keys()
        except ProposerError as error:
            raise click.ClickException(str(error)) from error
    return task, proposer


def execute(
    config: SearchConfig,
    store: RunStore,
    as_json: bool,
    proposer: Proposer,
    task: TaskBase,
    new_run: bool = False,
) -> None:
    """Run ``task`` (set up for the run's options) with a progress display on standard error
    (live on a terminal, plain lines elsewhere: see :class:`SearchProgress`), then print the
    result. A ``new_run`` whose cluster cannot be reached before anything was evaluated
    leaves no run folder behind."""
    console = Console(stderr=as_json, highlight=False)
    if not as_json:
        console.print(f"run folder: {store.path}", soft_wrap=True)
    resume = f"`sga-agent resume {store.path}` continues the run"
    recorded = store.recorded()
    shown = Console(stderr=True, highlight=False)
    assessing = as_task(task).describe_assessment(True)  # what the run's end does
    try:
        with (
            interrupts_stop_the_search(),
            SearchProgress(shown, config, recorded, assessing) as progress,
        ):
            result = runner.run(config, store, progress, proposer, task, command_started())
    except RayUnavailableError as error:  # no cluster: stop
        if new_run and not store.recorded().evaluations:  # it never started
            store.unlock()
            shutil.rmtree(store.path, ignore_errors=True)
            raise click.ClickException(f"{error}\nno run was started") from error
        raise click.ClickException(f"{error}\n{resume}") from error
    except ProposerError as error:  # no model: stop
        raise click.ClickException(f"{error}\n{resume}") from error
    except RunFolderFull as error:  # the disk is full: the message says what to do
        raise click.ClickException(str(error)) from error
    except KeyboardInterrupt:
        finished = counted(len(store.recorded().evaluations), "finished evaluation")
        click.echo(f"interrupted: {finished} recorded; {resume}", err=True)
        raise SystemExit(INTERRUPTED) from None
    print_result(console, store, result, as_json, task, config)
