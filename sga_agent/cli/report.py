"""``sga-agent report``: a static report of one run folder."""

from __future__ import annotations

import contextlib
import json
import sys
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
    help="Constitutive tasks: skip the free run of the best law (its error and pictures).",
)
@click.option("--json", "as_json", is_flag=True, help="Print the findings and the files as JSON.")
def report(run_dir: Path, out: Path | None, no_motion: bool, as_json: bool) -> None:
    """Write report.md and report.html (with PNG figures) for the run in RUN_DIR.

    It leads with a summary (the best loss against the seed's and the true law's, the ground
    truth, the best solution with its fitted constants, the free-run error of a law or the top
    molecules, the evaluations and screens counted as the search's end screen counts them),
    then the free run or the molecules, the bilevel picture, the best loss against
    evaluations and time, the inner-loop curves of the top 3 distinct solutions, the
    outcomes (of the screens too) and a table of every candidate (its status, cause of
    failure, fitted values, plan and parents, its screen and whether it was promoted, with its
    answer's analysis, plan and reasoning folded in); the settings, isolation record and raw
    feedback come last, folded.
    """
    from sga_agent.report import build_report

    try:  # with --json, stdout is for the JSON alone (Taichi announces itself there)
        with contextlib.redirect_stdout(sys.stderr if as_json else sys.stdout):
            paths, findings = build_report(run_dir, out, motion=not no_motion, say=_say)
    except RunStoreError as error:
        raise click.BadParameter(str(error), param_hint="'RUN_DIR'") from error
    if as_json:
        files = [str(path) for path in paths]
        click.echo(json.dumps({"run": str(run_dir), "files": files,
                               "findings": findings.to_dict()}, default=str))  # fmt: skip
        return
    for path in paths:
        click.echo(str(path))
