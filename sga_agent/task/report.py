"""What a task adds to a run's report: blocks of text, tables, figures and code, grouped in
sections, written from what the run recorded (see the report hooks of
:class:`sga_agent.task.TaskBase`).

``sga-agent report`` lays the blocks out as Markdown and HTML (:mod:`sga_agent.report.render`);
it imports no task. Standard library only (part of the protocol package :mod:`sga_agent.task`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

#: The report's figure style, for a task's figures to match the search's.
DPI = 150
FONT = {"font.size": 11, "axes.titlesize": 12, "axes.labelsize": 11, "legend.fontsize": 9}


@dataclass
class Text:
    """A paragraph; lines starting with ``- `` are a list."""

    text: str


@dataclass
class Table:
    header: list[str]
    rows: list[list[str]]


@dataclass
class Image:
    """A figure written into the report's folder (``file`` is its name there)."""

    file: str
    alt: str


@dataclass
class Code:
    text: str
    language: str = ""


Block = Text | Table | Image | Code


@dataclass
class Section:
    """A titled part of the report; ``collapsed`` ones are folded away (``<details>``)."""

    title: str
    blocks: list[Block] = field(default_factory=list)
    collapsed: bool = False


class CandidateRecord(Protocol):
    """An evaluated candidate as the report reads it back from the run folder."""

    id: str
    status: str
    loss: float
    code: str
    parameters: dict[str, float]
    extras: dict[str, Any]

    def artifacts(self) -> dict[str, Any]:
        """What the trusted fit left for reports (``Evaluation.artifacts``)."""
        ...


@dataclass
class ReportView:
    """What a task's report hooks see of a run.

    Parameters
    ----------
    task : str
        The run's task name.
    best : CandidateRecord or None
        The best scored candidate (None when nothing was scored).
    top : list of CandidateRecord
        The best distinct scored candidates, best first (three at most).
    assessment : Assessment or None
        What the task's ``assess`` said of the best candidate.
    folder : pathlib.Path
        The report's folder: figures go here, an :class:`Image` names them by file name.
    simulate : bool
        Whether simulations are allowed (``sga-agent report --no-motion`` says no).
    say : callable
        Tells the reader what a slow step is doing, before it starts.
    """

    task: str
    best: CandidateRecord | None
    top: list[CandidateRecord]
    assessment: Any = None
    folder: Path = Path(".")
    simulate: bool = True
    say: Callable[[str], None] = field(default=lambda text: None)
