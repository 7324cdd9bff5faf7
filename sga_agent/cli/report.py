"""``sga-agent report``: a static report of one run folder."""

from __future__ import annotations

import contextlib
import json
import sys
from pathlib import Path

import click
from rich.console import Console
from rich.progress import Progress, SpinnerColumn, TaskID, TextColumn, TimeElapsedColumn

from sga_agent.cli import main
from sga_agent.report.heartbeat import Heartbeat
from sga_agent.run_store import RunStoreError


def short(stage: str) -> str:
    """A stage's words without their details: "assessing the best solution" for "assessing the
    best solution: the true law's loss (...)"."""
    return stage.split(": ", 1)[0].split(" (", 1)[0]


class Stages:
    """What ``report`` tells on standard error while it works: each stage as it starts
    (``stage...``, as ``build_report``'s ``say`` is told) and how long it has run. On a terminal
    the time runs on a live line below, cleared at the end; elsewhere a plain line ("still
    assessing the best solution [0:00:10]", the stage's time) comes after each 5 s without a
    line, none in the command's first 5 s (:class:`~sga_agent.report.heartbeat.Heartbeat`)."""

    def __init__(self, console: Console) -> None:
        self.console = console
        self.live = Progress(
            SpinnerColumn(),
            TextColumn("{task.description}"),
            TimeElapsedColumn(),
            console=console,
            transient=True,
        )
        self.row: TaskID | None = None
        self.heartbeat = Heartbeat(stage_clock=True, active=not console.is_terminal)

    def __enter__(self) -> Stages:
        if self.console.is_terminal:
            self.live.start()
        self.heartbeat.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.heartbeat.stop()
        if self.console.is_terminal:
            self.live.stop()

    def __call__(self, stage: str) -> None:
        """``stage`` starts now."""
        if self.console.is_terminal:
            self.live.console.print(f"{stage}...", markup=False, highlight=False, soft_wrap=True)
            if self.row is not None:
                self.live.remove_task(self.row)
            self.row = self.live.add_task(short(stage), total=None)
            return
        click.echo(f"{stage}...", err=True)
        self.heartbeat.said()
        self.heartbeat.state(f"still {short(stage)}")


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
    feedback come last, folded. While it works, stderr names each stage as it starts (reading
    the run, the task's assessment of the best solution, the figures) and how long the running
    one has taken: a live line on a terminal, else, from 5 s on, a plain line every 5 s.
    """
    from sga_agent.report import build_report

    try:  # with --json, stdout is for the JSON alone (Taichi announces itself there)
        with (
            contextlib.redirect_stdout(sys.stderr if as_json else sys.stdout),
            Stages(Console(stderr=True, highlight=False)) as say,
        ):
            paths, findings = build_report(run_dir, out, motion=not no_motion, say=say)
    except RunStoreError as error:
        raise click.BadParameter(str(error), param_hint="'RUN_DIR'") from error
    if as_json:
        files = [str(path) for path in paths]
        click.echo(json.dumps({"run": str(run_dir), "files": files,
                               "findings": findings.to_dict()}, default=str))  # fmt: skip
        return
    for path in paths:
        click.echo(str(path))
