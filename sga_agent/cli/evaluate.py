"""``sga-agent evaluate``: score one solution file as the search does.

The same path as a search's candidate: the static checks, the confined capture, the trusted fit.
"""

from __future__ import annotations

import sys
import threading
import time
from pathlib import Path

import click
from rich.console import Console
from rich.progress import BarColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn
from rich.table import Table
from rich.text import Text

from sga_agent import registry
from sga_agent.cli import main
from sga_agent.cli.options import (
    check_device_here,
    task_options,
    task_or_factory,
    typed_task_options,
)
from sga_agent.cli.progress import PLAIN_GRACE_S, Count, PlainLines, clock, note_text
from sga_agent.natural_units import natural_values_of
from sga_agent.parsing import check_candidate, parse_response
from sga_agent.reading import read_answer
from sga_agent.sandbox import SandboxLimits, evaluate_in_sandbox, threads_per_worker
from sga_agent.task import CodeRejected, Evaluation, EvaluationSettings, FitProgress, Task
from sga_agent.task.device import DEVICES

_DEFAULTS = SandboxLimits()
#: Seconds between two plain lines of progress at most while the fit changes, and at least
#: while nothing does (see :class:`~sga_agent.cli.progress.PlainLines`).
PLAIN_EVERY_S = 1.0
PLAIN_QUIET_S = 5.0


def solution_in(text: str, task: Task) -> tuple[str | None, str, list[str]]:
    """The solution in a file's ``text``, its reason if it has none, and the slips fixed: a
    model's answer (fenced code blocks) is read as the search reads one
    (:func:`sga_agent.reading.read_answer`), a bare solution is taken as it is."""
    if not parse_response(text).blocks:
        return text, "", []
    reading = read_answer(text, task.kind, task.prompt_parts().template)
    return reading.code, reading.problem, reading.fixes


@main.command()
@click.option(
    "--task",
    "task_name",
    required=True,
    metavar="NAME",
    callback=task_or_factory,
    help="A registered task (see `sga-agent tasks`), or module:callable, a factory of a task "
    "under development, imported from the current directory.",
)
@click.argument("file", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "--epochs",
    type=click.IntRange(min=0),
    help="Steps of the inner optimization [default: the task's].",
)
@click.option(
    "--lr",
    "learning_rate",
    type=click.FloatRange(min=0, min_open=True),
    help="Learning rate of the inner optimization [default: the task's].",
)
@click.option(
    "--option",
    "options",
    multiple=True,
    callback=task_options,
    metavar="KEY=VALUE",
    help="Task option, repeatable (e.g. steps=200, optimizer=lbfgs for the constitutive tasks); "
    "unknown keys and bad values are usage errors.",
)
@click.option(
    "--json",
    "as_json",
    is_flag=True,
    help="Print only the evaluation as JSON (with the traceback of a failure, if any).",
)
@click.option(
    "--timeout",
    "timeout_s",
    type=click.FloatRange(min=0, min_open=True),
    default=_DEFAULTS.timeout_s,
    show_default=True,
    help="Wall-clock limit of the evaluation, in seconds.",
)
@click.option(
    "--memory-mb",
    type=click.IntRange(min=64),
    default=_DEFAULTS.memory_mb,
    show_default=True,
    help="Memory limit in MiB of the capture and of the fit (Taichi alone takes about 1.2 GiB).",
)
@click.option(
    "--device",
    type=click.Choice(DEVICES),
    default=_DEFAULTS.device,
    show_default=True,
    help="Where the fit computes: Taichi's kernels on this CPU or on a CUDA GPU (checked "
    "before anything starts).",
)
def evaluate(
    task_name: str,
    file: Path,
    epochs: int | None,
    learning_rate: float | None,
    options: dict[str, str],
    as_json: bool,
    timeout_s: float,
    memory_mb: int,
    device: str,
) -> None:
    """Score the solution in FILE for a task, exactly as the search does.

    The code passes the search's static checks, runs only in the confined capture process, and
    is fitted by a trusted process from what the capture recorded. FILE is a solution (a law's
    .py file, a molecule block) or a model's answer, read as the search reads one (the block
    that defines the solution, its slips fixed and printed as "read as: ...").
    Prints the fitted parameters, the loss and the feedback; an invalid solution prints its
    reason to stderr and exits with status 1. While it works, stderr shows what runs (the
    capture, the fit worker's start and warm-up, the fit's epochs with their loss): a live
    line on a terminal, else (after 5 s) a plain line at least every 5 s.
    """
    try:
        text = file.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise click.BadParameter(f"cannot read '{file}': {error}", param_hint="'FILE'") from error
    check_device_here(device)
    extra_path = [Path.cwd()] if ":" in task_name else []
    task = _task(task_name, extra_path)
    typed = typed_task_options(task, options)
    limits = SandboxLimits(timeout_s=timeout_s, memory_mb=memory_mb, threads=threads_per_worker(1),
                           device=device)  # fmt: skip
    settings = EvaluationSettings(epochs=epochs, learning_rate=learning_rate, options=typed)
    solution, problem, fixes = solution_in(text, task)
    for fix in fixes:
        click.echo(f"read as: {fix}", err=True)
    try:
        if solution is None:
            raise CodeRejected(problem)
        check_candidate(solution, task)
    except CodeRejected as error:
        evaluation = Evaluation.invalid(f"the code breaks the rules: {error}")
    else:
        with FitDisplay(Console(stderr=True, highlight=False)) as display:
            evaluation = evaluate_in_sandbox(
                task_name, solution, settings, limits, extra_python_path=extra_path,
                progress=display,
            )  # fmt: skip
    if as_json:
        click.echo(evaluation.to_json())
    elif evaluation.valid:
        _show(evaluation, task, solution or "")
    if not evaluation.valid:
        click.echo(f"invalid: {evaluation.reason}", err=True)
        sys.exit(1)


class FitDisplay:
    """What ``evaluate`` shows on standard error while the sandbox works: the stage running
    and the fit's epochs (:class:`~sga_agent.task.FitProgress` notes). On a terminal a live
    line, cleared at the end; elsewhere plain lines (:class:`~sga_agent.cli.progress.PlainLines`:
    none in the first :data:`~sga_agent.cli.progress.PLAIN_GRACE_S` seconds, then at most one
    each :data:`PLAIN_EVERY_S`, at least one each :data:`PLAIN_QUIET_S`)."""

    def __init__(self, console: Console) -> None:
        self.progress = Progress(
            SpinnerColumn(),
            TextColumn("{task.description}"),
            BarColumn(bar_width=16),
            Count(),
            TimeElapsedColumn(),
            TextColumn("{task.fields[status]}"),
            console=console,
            transient=True,
        )
        self.row = self.progress.add_task("starting", total=None, status="")
        self._lock = threading.Lock()
        self.note = FitProgress("starting")
        self.started = time.monotonic()
        self.plain = None if console.is_terminal else PlainLines(
            console, self._line, PLAIN_EVERY_S, PLAIN_QUIET_S, PLAIN_GRACE_S
        )  # fmt: skip

    def __enter__(self) -> FitDisplay:
        self.started = time.monotonic()
        if self.plain is not None:
            self.plain.start()
        else:
            self.progress.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        if self.plain is not None:
            self.plain.stop()
        else:
            self.progress.stop()

    def __call__(self, note: FitProgress) -> None:
        with self._lock:
            self.note = note
        loss = "" if note.loss is None else f"loss {note.loss:.4g}"
        counts = {} if note.epochs is None else {"completed": note.epoch, "total": note.epochs}
        self.progress.update(self.row, description=note.stage, status=loss, **counts)
        if self.plain is not None:
            self.plain.changed()

    def _line(self) -> str:
        with self._lock:
            return f"{note_text(self.note)} [{clock(time.monotonic() - self.started)}]"


def _task(task_name: str, extra_path: list[Path]) -> Task:
    """The task, for its kind and options (a factory's module is imported from here)."""
    sys.path[:0] = [str(path) for path in extra_path]
    try:
        return registry.resolve_task(task_name)
    finally:
        del sys.path[: len(extra_path)]


def _show(evaluation: Evaluation, task: Task | None = None, solution: str = "") -> None:
    """The fitted parameters (with what a ``log_X`` one stands for: X in natural units, see
    :mod:`sga_agent.natural_units`), the loss and the feedback."""
    console = Console(highlight=False)
    if evaluation.parameters:
        natural = natural_values_of(task, solution, evaluation.parameters)
        columns = ["parameter", "value", *(["stands for"] if natural else [])]
        table = Table(*columns, title="fitted parameters")
        for name, value in evaluation.parameters.items():
            meaning = [str(natural[name]) if name in natural else ""] if natural else []
            table.add_row(name, f"{value:.6g}", *meaning)
        console.print(table)
    console.print(f"loss: {evaluation.loss:.6g}   ({evaluation.seconds:.1f} s)")
    console.print(Text("feedback:", style="bold"))
    console.print(Text(evaluation.feedback))
