"""The loss-versus-size front of a run: for each size, the best loss of a solution no larger,
as symbolic-regression tools keep their hall of fame.

A solution's size is the task's (``TaskBase.solution_size``: the operations of a captured law);
a task that gives none has no front. Of the run's distinct scored solutions, the front keeps
each one whose loss is below that of every smaller one. Its score, as PySR reports it, is how
fast the log of the loss falls per unit of size from the previous member: a large score marks a
term that pays for itself, a small one a term the data barely need.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from sga_agent.report.data import Candidate, Run
from sga_agent.report.findings import distinct
from sga_agent.report.plots import new_figure, save
from sga_agent.report.render import Image, Section, Table, Text
from sga_agent.task import TaskBase


@dataclass(frozen=True)
class Member:
    """A solution on the front: its size, its loss and the score from the previous member."""

    candidate: Candidate
    size: int
    score: float | None


def sized(run: Run, task: TaskBase) -> list[tuple[Candidate, int]]:
    """The run's distinct scored solutions with a positive finite loss and a size."""
    found = []
    for candidate in distinct(run, task, len(run.candidates)):
        size = task.solution_size(candidate)
        if size is not None and math.isfinite(candidate.loss) and candidate.loss > 0:
            found.append((candidate, size))
    return found


def front(solutions: list[tuple[Candidate, int]]) -> list[Member]:
    """The members of the front of ``solutions`` (candidate, size), smallest first."""
    members: list[Member] = []
    for candidate, size in sorted(solutions, key=lambda pair: (pair[1], pair[0].loss)):
        if members and candidate.loss >= members[-1].candidate.loss:
            continue
        if members and members[-1].size == size:
            continue  # sorted by loss within a size: the first is that size's best
        score = None
        if members:
            previous = members[-1]
            score = math.log(previous.candidate.loss / candidate.loss) / (size - previous.size)
        members.append(Member(candidate, size, score))
    return members


def front_section(run: Run, task: TaskBase | None, folder: Path, label: str) -> Section | None:
    """The report's section: every distinct solution's loss against its size, the front drawn
    through them, and the front as a table (None when the task gives no sizes)."""
    if task is None:
        return None
    solutions = sized(run, task)
    if not solutions:
        return None
    members = front(solutions)
    path = plot_front(solutions, members, folder / "front.png", label, run.task)
    rows = [[str(m.size), f"{m.candidate.loss:.4g}", _score(m.score), m.candidate.id]
            for m in members]  # fmt: skip
    return Section("Loss against size", [
        Text(f"Each distinct scored solution's loss against its size ({task.size_label}); the "
             "line is the front: the best loss at each size or below. A member's score is how "
             "fast the log of the loss falls per unit of size from the member before it: a "
             "small score marks terms the data barely need."),
        Image(path.name, "loss against size"),
        Table(["size", "loss", "score", "candidate"], rows),
    ])  # fmt: skip


def plot_front(
    solutions: list[tuple[Candidate, int]], members: list[Member], path: Path, label: str,
    task: str,
) -> Path:  # fmt: skip
    """The scatter of ``solutions`` and the front through ``members``, log loss."""
    figure = new_figure(6.5, 4.0)
    axes = figure.subplots()
    axes.scatter([size for _, size in solutions], [c.loss for c, _ in solutions], s=14,
                 color="#b0bec5", label="distinct solutions")  # fmt: skip
    axes.step([m.size for m in members], [m.candidate.loss for m in members], where="post",
              color="#264653", marker="o", markersize=4, label="front")  # fmt: skip
    axes.set_yscale("log")
    axes.set_xlabel("size")
    axes.set_ylabel(label)
    axes.grid(True, which="both", alpha=0.3)
    axes.legend()
    axes.set_title(f"{task}: loss against size")
    return save(figure, path)


def _score(score: float | None) -> str:
    return "" if score is None else f"{score:.3g}"
