"""The events of a run: one class per line type of a run folder's ``events.jsonl``.

Every event is written as a JSON object whose ``"type"`` is the class's :attr:`Event.type`,
followed by its fields (``to_dict``); readers compare ``event["type"]`` with those same
attributes, so each type is spelled once, here. The strings are the run-folder format: runs
recorded earlier are read back with them, so they never change.

Two kinds of event are only shown, never written: :class:`FitsStarted` and
:class:`FitProgressed` tell a progress display which evaluations run and how far each has come
(a fit's epochs), without adding a line per epoch to the log.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any, ClassVar


@dataclass(frozen=True)
class Event:
    """Base of the run events; ``to_dict`` gives the JSON object written to the log."""

    type: ClassVar[str]

    def to_dict(self) -> dict[str, Any]:
        """``{"type": ..., field: value, ...}``; fields that are None are left out."""
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        return {"type": self.type, **{k: v for k, v in values.items() if v is not None}}


@dataclass(frozen=True)
class RunStarted(Event):
    """A run folder was created; ``meta`` (e.g. the proposer) is spread into the event."""

    type: ClassVar[str] = "run_started"
    meta: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"type": self.type, **self.meta}


@dataclass(frozen=True)
class RunResumed(Event):
    """A stopped run was continued (on another Ray cluster when ``ray_address`` is set; with
    a new wall-time budget, in seconds over all its sessions, when ``max_seconds`` is)."""

    type: ClassVar[str] = "resumed"
    ray_address: str | None = None
    max_seconds: float | None = None


@dataclass(frozen=True)
class SandboxReady(Event):
    """How the run's workers are isolated, and where they run (spread into the event)."""

    type: ClassVar[str] = "sandbox"
    isolation: dict[str, Any]
    placement: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"type": self.type, "isolation": self.isolation, **self.placement}


@dataclass(frozen=True)
class SearchStarted(Event):
    """The search loop began; ``resumed`` when the run already held evaluations;
    ``start_up``: the seconds its session spent before (the program's start-up), which count
    in the run's wall time."""

    type: ClassVar[str] = "search_started"
    resumed: bool
    start_up: float | None = None


@dataclass(frozen=True)
class ProposalReceived(Event):
    """A proposer's answer for a candidate (``Proposal.to_dict()``)."""

    type: ClassVar[str] = "proposal"
    candidate: str
    proposal: dict[str, Any]


@dataclass(frozen=True)
class ProposalMissing(Event):
    """No answer came for a candidate slot."""

    type: ClassVar[str] = "proposal_missing"
    candidate: str


@dataclass(frozen=True)
class ProposerFailed(Event):
    """The proposer raised; a ``transient`` failure lets the search go on."""

    type: ClassVar[str] = "proposer_error"
    error: str
    transient: bool


@dataclass(frozen=True)
class CandidateEvaluated(Event):
    """A candidate's finished evaluation (``Evaluation.to_dict()`` without its artifacts)."""

    type: ClassVar[str] = "evaluation"
    candidate: str
    evaluation: dict[str, Any]


@dataclass(frozen=True)
class CandidateScreened(Event):
    """A candidate's finished screen: its evaluation at the reduced ``fidelity`` of a
    multi-fidelity search (``Evaluation.to_dict()`` without its artifacts). Its loss is
    comparable only with other screens'; the full fit, if the candidate is promoted to it, is
    its ``evaluation`` event."""

    type: ClassVar[str] = "screened"
    candidate: str
    fidelity: float
    evaluation: dict[str, Any]


@dataclass(frozen=True)
class IterationStarted(Event):
    """An outer iteration begins: its proposals are asked for next."""

    type: ClassVar[str] = "iteration_started"
    iteration: int


@dataclass(frozen=True)
class IterationDone(Event):
    """An outer iteration ended; ``top`` holds the heap's best entries' summaries, ``tokens``
    and ``cost_usd`` what its answers cost (None in runs recorded before they were)."""

    type: ClassVar[str] = "iteration_done"
    iteration: int
    top: list[dict[str, Any]]
    tokens: int | None = None
    cost_usd: float | None = None


@dataclass(frozen=True)
class RunFinished(Event):
    """The search ended, every iteration run (``stopped`` empty) or stopped by a budget."""

    type: ClassVar[str] = "run_finished"
    stopped: str


@dataclass(frozen=True)
class EvaluationsStopped(Event):
    """The wall-time budget ran out while the ``candidates``' evaluations (screens, at
    ``fidelity`` below 1, or full fits) ran: they were stopped and nothing of them recorded,
    so a resume with a larger budget evaluates them again."""

    type: ClassVar[str] = "evaluations_stopped"
    candidates: list[str]
    fidelity: float = 1.0
    reason: str = ""


# ---------------------------------------------------------------------- shown, never recorded


@dataclass(frozen=True)
class FitsStarted(Event):
    """Evaluations were submitted together: the ``candidates``' full fits (``fidelity`` 1) or
    their screens (below 1). Shown, never recorded."""

    type: ClassVar[str] = "fits_started"
    candidates: list[str]
    fidelity: float


@dataclass(frozen=True)
class FitProgressed(Event):
    """How far a running evaluation of ``candidate`` has come: its latest progress ``note``
    (:meth:`sga_agent.task.FitProgress.to_dict`). Shown, never recorded; it comes from the
    evaluator's thread."""

    type: ClassVar[str] = "fit_progress"
    candidate: str
    note: dict[str, Any]
