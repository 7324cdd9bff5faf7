"""The records a task and the search exchange: settings, evaluations, prompt text, what a task
knows of a run's best solution, the parents a built-in proposer works from.

Standard library only (part of the protocol package :mod:`sga_agent.task`).
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import asdict, dataclass, field
from typing import Any, Literal, TypeVar

TaskKind = Literal["equation", "entity"]
_Options = TypeVar("_Options")
#: Outcome of an evaluation: scored, or why not (invalid code, an exception, NaN/inf, a limit).
STATUSES = ("ok", "invalid", "error", "unstable", "timeout", "out_of_memory", "crashed")


@dataclass(frozen=True)
class EvaluationSettings:
    """How hard a task's inner optimization works on one candidate.

    Parameters
    ----------
    epochs : int, optional
        Inner-optimization steps; ``None`` uses the task's default.
    learning_rate : float, optional
        Step size of the inner optimizer; ``None`` uses the task's default.
    seed : int
        Seed for any randomness of the evaluation.
    options : object, optional
        The task's options: an object of its ``options_type`` (see :class:`Task`), as the
        search and its fit workers always pass them; ``None`` (a direct call) for their
        defaults. A task reads them with :meth:`options_as`.
    fidelity : float
        The share of the full fit's work this evaluation may spend, in (0, 1]: 1 is the full
        fit; less is a cheaper screen (a multi-fidelity search screens every candidate and
        fits only the most promising fully). The task decides how to cut the work (the
        constitutive tasks fit fewer epochs on the first segments of the horizon); a task
        that cannot screen runs its full fit. Losses of different fidelities are not
        comparable: the search never ranks one against the other.
    """

    epochs: int | None = None
    learning_rate: float | None = None
    seed: int = 0
    options: Any = None
    fidelity: float = 1.0

    def __post_init__(self) -> None:
        if self.epochs is not None and (not isinstance(self.epochs, int) or self.epochs < 0):
            raise ValueError(f"epochs must be a non-negative integer or None, got {self.epochs!r}")
        if self.learning_rate is not None and not self.learning_rate > 0:
            raise ValueError(f"learning_rate must be positive, got {self.learning_rate!r}")
        if isinstance(self.fidelity, bool) or not 0 < self.fidelity <= 1:
            raise ValueError(f"fidelity must lie in (0, 1], got {self.fidelity!r}")

    def options_as(self, options_type: type[_Options]) -> _Options:
        """The options as an ``options_type`` object: themselves, or its defaults for None.

        Raises
        ------
        TypeError
            The options are of another type (a dict of them, say: build the dataclass).
        """
        if self.options is None:
            return options_type()
        if not isinstance(self.options, options_type):
            raise TypeError(
                f"settings.options must be a {options_type.__name__} (or None for its "
                f"defaults), got {type(self.options).__name__}"
            )
        return self.options


#: How native libraries (torch's allocator, Taichi) report a failed allocation.
_ALLOCATION_FAILURE = re.compile(r"allocate memory|memory allocation|out of memory", re.IGNORECASE)


def is_out_of_memory(error: BaseException) -> bool:
    """Whether ``error`` is a failed allocation (an ``out_of_memory`` outcome)."""
    return isinstance(error, MemoryError) or bool(_ALLOCATION_FAILURE.search(str(error)))


class InvalidSolution(ValueError):
    """Raised by ``Task.capture`` for a solution that cannot be used; one line for the model."""


@dataclass
class Evaluation:
    """Outcome of evaluating one candidate solution.

    ``valid`` is False when the candidate could not be scored; ``status`` says how (one of
    :data:`STATUSES`: "invalid" code, an "error" raised, "unstable" NaN/inf, or a sandbox limit:
    "timeout", "out_of_memory", "crashed"), ``reason`` says why in one line and ``loss`` is inf.
    ``feedback`` is the text shown to the model in later prompts. ``parameters`` are the fitted
    values of the best epoch, ``curves`` maps a name ("loss", a parameter name) to its values
    over the inner optimization, ``extras`` holds any further JSON-serialisable record and
    ``artifacts`` larger data that reports draw from (kept in the candidate's folder, not in the
    run's event log), such as the best epoch's trajectory.
    """

    valid: bool
    loss: float
    feedback: str
    reason: str = ""
    parameters: dict[str, float] = field(default_factory=dict)
    curves: dict[str, list[float]] = field(default_factory=dict)
    extras: dict[str, Any] = field(default_factory=dict)
    seconds: float = 0.0
    status: str = "ok"
    artifacts: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise ValueError(f"status must be one of {STATUSES}, got {self.status!r}")

    @classmethod
    def invalid(
        cls, reason: str, feedback: str | None = None, status: str = "invalid", **fields: Any
    ) -> Evaluation:
        """An unscored candidate: infinite loss, the reason doubling as feedback by default."""
        text = feedback if feedback is not None else reason
        return cls(False, math.inf, text, reason, status=status, **fields)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable dict (an infinite loss becomes the string "inf")."""
        data = asdict(self)
        data["loss"] = _encode_float(self.loss)
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Evaluation:
        """Inverse of :meth:`to_dict`."""
        data = dict(data)
        data["loss"] = float(data["loss"])
        return cls(**data)

    def to_json(self) -> str:
        return json.dumps(self.to_dict())


def _encode_float(value: float) -> float | str:
    return value if math.isfinite(value) else str(value)


@dataclass(frozen=True)
class PromptParts:
    """The task-specific text the prompt templates are filled with.

    Parameters
    ----------
    role : str
        Who the model is asked to be (the system prompt's expertise sentence).
    context : str
        What is being searched for and how a solution is scored.
    template : str
        The code skeleton every proposal must follow.
    requirements : str
        Task-specific rules for the code (shapes, units, allowed operations, tips).
    """

    role: str
    context: str
    template: str
    requirements: str


@dataclass(frozen=True)
class NoOptions:
    """The options of a task that declares none."""


@dataclass
class Assessment:
    """What only the task knows about a run's best solution (``Task.assess``).

    Parameters
    ----------
    truth : str
        The ground truth's name ("" when the task has none).
    truth_loss : float, optional
        The ground truth's loss when scored like a candidate.
    derived : dict of str to float
        Values derived from the fitted parameters that read better than them
        (``{"exp(log_E)": 4.4e5}``).
    free_run : object, optional
        The task's own record of the best solution run on its own (the constitutive tasks'
        ``FreeRun``: simulated from the initial state without teacher forcing). The agent only
        calls its ``to_dict()`` (``summary.json``'s ``free_run``); the task's report hooks
        read the rest.
    held_out : object, optional
        The same record of the best solution on a held-out scene: an observation it was not
        fitted to (``summary.json``'s ``held_out``).
    verdict : str
        One plain sentence: whether the best solution does what was asked (reproduces the
        observed motion), by the task's own thresholds ("" when the task cannot tell).
    """

    truth: str = ""
    truth_loss: float | None = None
    derived: dict[str, float] = field(default_factory=dict)
    free_run: Any = None
    held_out: Any = None
    verdict: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "truth": self.truth, "truth_loss": self.truth_loss, "derived": self.derived,
            "free_run": None if self.free_run is None else self.free_run.to_dict(),
            "held_out": None if self.held_out is None else self.held_out.to_dict(),
            "verdict": self.verdict,
        }  # fmt: skip


@dataclass(frozen=True)
class Parent:
    """An evaluated solution a built-in proposer may mutate or cross: its code, its loss and
    the fitted values of its continuous parameters (``Evaluation.parameters``; empty when none
    were fitted), so a child may start where its parent's inner optimization ended."""

    code: str
    loss: float
    parameters: dict[str, float] = field(default_factory=dict)


@dataclass
class Simplified:
    """The best solution with the parts the data do not need dropped (``Task.simplify``).

    Parameters
    ----------
    solution : str
        The simplified solution, its fitted values written in.
    dropped : list of str
        What was dropped, in words ("the term scaled by log_modulus2").
    loss : float
        The loss without them, nothing refitted.
    base_loss : float
        The loss with them, computed the same way.
    band : float
        The loss the noise allows (:func:`~sga_agent.task.within_noise` of ``base_loss``).
    formula : str
        The simplified solution as one formula, where the task writes one (``Task.formula``).
    """

    solution: str
    dropped: list[str]
    loss: float
    base_loss: float
    band: float
    formula: str = ""

    @property
    def sentence(self) -> str:
        """What was dropped and what it cost, in one sentence."""
        parts = ", ".join(self.dropped)
        one = len(self.dropped) == 1
        return (f"{len(self.dropped)} of its parts {'costs' if one else 'cost'} less than the "
                f"noise and {'is' if one else 'are'} dropped ({parts}): the loss goes from "
                f"{self.base_loss:.3g} to {self.loss:.3g}, {self.band:.3g} at most")  # fmt: skip

    def to_dict(self) -> dict[str, Any]:
        return {"solution": self.solution, "dropped": self.dropped, "loss": self.loss,
                "base_loss": self.base_loss, "band": self.band, "sentence": self.sentence,
                "formula": self.formula or None}
