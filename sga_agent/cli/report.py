"""``sga-agent report``: a static report of one run folder."""

from __future__ import annotations

from pathlib import Path

import click

from sga_agent.cli import main
from sga_agent.run_store import RunStoreError


def _say(text: str) -> None:
    click.echo(f"{text}...", err=True)


@main.command()
@click.argument("run_dir", type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option(
    "--out-dir",
    "out",
    type=click.Path(file_okay=False, path_type=Path),
    show_default="RUN_DIR/report",
    help="Folder for the report.",
)
@click.option(
    "--no-motion",
    is_flag=True,
    help="Constitutive tasks: skip re-simulating the best law for the motion picture.",
)
def report(run_dir: Path, out: Path | None, no_motion: bool) -> None:
    """Write report.md and report.html (with PNG figures) for the run in RUN_DIR.

    Sections: summary, best loss per iteration, outcomes per iteration, inner-loop curves of
    the top 3, the best solution's code and feedback, and a task picture (the motion of the best
    law against the observation, or the top molecules).
    """
    from sga_agent.report import build_report

    try:
        paths = build_report(run_dir, out, motion=not no_motion, say=_say)
    except RunStoreError as error:
        raise click.BadParameter(str(error), param_hint="'RUN_DIR'") from error
    for path in paths:
        click.echo(str(path))
