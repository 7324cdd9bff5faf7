"""Test doubles for the sandbox and the CLI: tasks that import nothing heavy.

:class:`ExecTask` executes the candidate's text (as a real task would run a proposed law) and
reports the names it defines (``loss``, ``parameters``, ``feedback`` and ``report``, any JSON
value), plus the worker's environment and working directory, so that the tests can see what the
sandbox did.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, ClassVar

from sga_agent.task import Evaluation, EvaluationSettings, PromptParts, report_progress


@dataclass(frozen=True)
class DoubleOptions:
    """The doubles' options: ``label``, any text, reported back with the settings; ``notes``,
    the file :class:`StagedWarmingTask` notes its warm-up stages in. ``built`` counts the
    objects this process has built."""

    label: str = ""
    notes: str | None = None
    built: ClassVar[int] = 0

    def __post_init__(self) -> None:
        DoubleOptions.built += 1


class ExecTask:
    """Runs the solution; ``loss`` and ``parameters`` are read from the names it defines."""

    name = "exec-double"
    description = "Executes the candidate and reports what it defined (a test double)."
    kind = "equation"
    options_type = DoubleOptions

    def seed_solution(self) -> str:
        return "loss = 1.0\nparameters = {'E': 2.0}\n"

    def prompt_parts(self) -> PromptParts:
        return PromptParts(role="tester", context="", template="", requirements="")

    def capture(self, solution: str) -> dict[str, Any]:
        namespace: dict = {}
        exec(solution, namespace)
        return {
            "loss": float(namespace.get("loss", 0.0)),
            "feedback": str(namespace.get("feedback", "ran")),
            "parameters": dict(namespace.get("parameters", {})),
            "report": namespace.get("report"),
            "environ": dict(os.environ),
            "uid": os.getuid(),
            "pid": os.getpid(),
        }

    def evaluate(self, data: dict[str, Any], settings: EvaluationSettings) -> Evaluation:
        return Evaluation(
            valid=True,
            loss=data["loss"],
            feedback=data["feedback"],
            parameters=data["parameters"],
            extras={
                "environ": data["environ"],
                "uid": data["uid"],
                "pid": data["pid"],
                "settings": asdict(settings),
                "report": data["report"],
            },
        )


class WarmingTask(ExecTask):
    """:class:`ExecTask` whose fit worker warms up first; its evaluations report the options
    the warm-up was given (their type's name and fields), how many options objects the fit
    worker has built and its process id."""

    warmed_with: dict[str, Any] | None = None

    def warm_up_fit(self, options: DoubleOptions) -> None:
        WarmingTask.warmed_with = {"type": type(options).__name__, **asdict(options)}

    def evaluate(self, data: dict[str, Any], settings: EvaluationSettings) -> Evaluation:
        evaluation = super().evaluate(data, settings)
        evaluation.extras.update(warmed_with=WarmingTask.warmed_with, fit_pid=os.getpid(),
                                 options_built=DoubleOptions.built)  # fmt: skip
        return evaluation


class StagedWarmingTask(ExecTask):
    """:class:`ExecTask` whose fit warm-up comes in three stages, each noted as it runs in the
    file named by the option ``notes``; its evaluations report the stages run before them."""

    def warm_up_fit(self, options: DoubleOptions) -> Iterator[None]:
        notes = Path(options.notes)
        for stage in ("1", "2", "3"):
            with notes.open("a", encoding="utf-8") as file:
                file.write(stage + "\n")
            yield

    def evaluate(self, data: dict[str, Any], settings: EvaluationSettings) -> Evaluation:
        evaluation = super().evaluate(data, settings)
        notes = Path(settings.options.notes)
        evaluation.extras["stages_done"] = notes.read_text().split() if notes.exists() else []
        return evaluation


class FailingWarmUpTask(ExecTask):
    """:class:`ExecTask` whose fit warm-up raises."""

    def warm_up_fit(self, options: DoubleOptions) -> None:
        raise RuntimeError("no data to load")


class ReportingTask(ExecTask):
    """:class:`ExecTask` whose fit reports its progress: ``settings.epochs`` epochs (default 3)
    counting down to its loss, between malformed notes (a stage that is no text, a count that
    is no integer, control characters, a stage far too long)."""

    def evaluate(self, data: dict[str, Any], settings: EvaluationSettings) -> Evaluation:
        epochs = 3 if settings.epochs is None else settings.epochs
        report_progress(123)  # type: ignore[arg-type]
        report_progress("fitting", loss="low")  # type: ignore[arg-type]
        for epoch in range(1, epochs + 1):
            report_progress("fitting", epoch, epochs, data["loss"] + epochs - epoch)
            report_progress("\x1b[2J\rfit\x07 " + "x" * 500, epoch=True)  # type: ignore[arg-type]
        return super().evaluate(data, settings)


class ExecLawTask(ExecTask):
    """:class:`ExecTask` for solutions that pass the search's static checks of an equation
    (a ``Physics`` module, torch imports), as ``sga-agent evaluate`` applies them."""

    capture_modules = ("torch", "torch.nn")

    def seed_solution(self) -> str:
        return law_solution("loss = 1.0")


def law_solution(body: str) -> str:
    """A solution that passes the static checks and runs ``body`` at module level."""
    return (
        "import torch\nimport torch.nn as nn\n\n"
        f"{body}\n\n\n"
        "class Physics(nn.Module):\n"
        "    def __init__(self, scale: float = 1.0):\n"
        "        super().__init__()\n"
        "        self.scale = nn.Parameter(torch.tensor(scale))\n\n"
        "    def forward(self, F: torch.Tensor) -> torch.Tensor:\n"
        "        return F * self.scale\n"
    )


def not_a_task() -> object:
    """A factory returning something that is not a Task."""
    return object()


def broken_task() -> ExecTask:
    """A factory that fails, as a plugin with a bug would."""
    raise RuntimeError("this plugin is broken")


class HealthTask(ExecTask):
    """:class:`ExecTask` for the slot's recycling and blame tests. Its fit warms up in three
    stages and reports its process id, the stages it had run and the evaluations it ran before
    (``fit_pid``, ``warm_stages``, ``earlier``). The candidate's ``report`` says what the fit
    does besides: ``{"leak_mb": n}`` keeps n MB resident for good; ``{"oom": "always"}``
    raises MemoryError, ``{"oom": "grown"}`` only in a worker that has evaluated before;
    ``{"wait": PATH}`` writes ``PATH.fitting-PID`` and waits (at most a minute) for PATH to
    exist; ``{"sleep": s}`` sleeps s seconds (in the fit; the capture sleeps
    ``capture_sleep``), with ``{"marks": DIR}`` in a file ``DIR/fitting-PID`` meanwhile."""

    warm_stages = 0
    earlier = 0
    kept: list[bytes] = []

    def capture(self, solution: str) -> dict[str, Any]:
        data = super().capture(solution)
        report = data["report"] if isinstance(data["report"], dict) else {}
        time.sleep(float(report.get("capture_sleep", 0)))
        return data

    def warm_up_fit(self, options: DoubleOptions) -> Iterator[None]:
        for _ in range(3):
            time.sleep(0.05)
            HealthTask.warm_stages += 1
            yield

    def evaluate(self, data: dict[str, Any], settings: EvaluationSettings) -> Evaluation:
        report = data["report"] if isinstance(data["report"], dict) else {}
        earlier, HealthTask.earlier = HealthTask.earlier, HealthTask.earlier + 1
        if report.get("oom") == "always" or (report.get("oom") == "grown" and earlier):
            raise MemoryError("the double was asked to run out of memory")
        HealthTask.kept.append(b"x" * (int(report.get("leak_mb", 0)) * 2**20))
        if "wait" in report:
            waiting = Path(f"{report['wait']}.fitting-{os.getpid()}")
            waiting.write_text("")
            deadline = time.monotonic() + 60
            while not os.path.exists(report["wait"]) and time.monotonic() < deadline:
                time.sleep(0.02)
            waiting.unlink()
        marks = Path(report.get("marks", "")) / f"fitting-{os.getpid()}"
        if "marks" in report:
            marks.write_text("")
        time.sleep(float(report.get("sleep", 0)))
        if "marks" in report:
            marks.unlink(missing_ok=True)
        evaluation = super().evaluate(data, settings)
        del evaluation.extras["environ"]
        evaluation.extras.update(fit_pid=os.getpid(), warm_stages=HealthTask.warm_stages,
                                 earlier=earlier)  # fmt: skip
        return evaluation
