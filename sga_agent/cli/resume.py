"""``sga-agent resume``: continue a search that was stopped or killed."""

from __future__ import annotations

from pathlib import Path

import click

from sga_agent.cli import main
from sga_agent.cli.search import execute, make_proposer
from sga_agent.run_store import RunStore, RunStoreError


@main.command()
@click.argument("run_dir", type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print only the summary as JSON.")
def resume(run_dir: Path, as_json: bool) -> None:
    """Continue the search recorded in RUN_DIR.

    Recorded model answers are not asked again and finished evaluations are not re-run; the
    search goes on from where it stopped with the run's own settings.
    """
    try:
        store = RunStore.open(run_dir)
        config = store.config()
    except RunStoreError as error:
        raise click.BadParameter(str(error), param_hint="'RUN_DIR'") from error
    proposer = make_proposer(config)
    store.append({"type": "resumed"})
    execute(config, store, as_json, proposer)
