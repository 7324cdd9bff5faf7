"""The contract between the search and a scientific task.

A task plugin (a constitutive-law search, a molecule design, a third party's problem) is an
object satisfying :class:`Task`. The search only ever sees solutions as text (the code block a
proposer wrote) and :class:`Evaluation` records. A solution is scored in two steps so that its
code can never forge its score:

- ``capture(solution) -> data``: the only place where a solution's code may run, in a confined
  capture process (:mod:`sga_agent.capture_server`). It turns the solution into inert JSON data
  (a law's graph of tensor operations; a molecule's SMILES and coordinates). Whatever comes out
  of this step is untrusted.
- ``evaluate(data, settings) -> Evaluation``: trusted. It runs in a fit process
  (:mod:`sga_agent.fit_worker`) that never imports or runs solution code; it checks the data
  and scores it.

This module has no dependency beyond the standard library so that task packages can import it
cheaply.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, Literal, Protocol, runtime_checkable

TaskKind = Literal["equation", "entity"]
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
    options : dict
        Task-specific settings: fields of the task's ``options_type`` (see :class:`Task`).
    """

    epochs: int | None = None
    learning_rate: float | None = None
    seed: int = 0
    options: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.epochs is not None and (not isinstance(self.epochs, int) or self.epochs < 0):
            raise ValueError(f"epochs must be a non-negative integer or None, got {self.epochs!r}")
        if self.learning_rate is not None and not self.learning_rate > 0:
            raise ValueError(f"learning_rate must be positive, got {self.learning_rate!r}")


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


def options_type(task: object) -> type:
    """The dataclass of ``task``'s options: its ``options_type``, else :class:`NoOptions`."""
    return getattr(task, "options_type", NoOptions)


@dataclass
class FreeRun:
    """A solution simulated from the initial state without teacher forcing, against the
    observation: the root-mean-square position error at the last step and averaged over the
    steps, in units of the body's size (``body_size``, m); infinite when the simulation blew up
    (``unstable`` says where). ``frames`` are steps at which ``positions`` and ``observed``
    ((frames, N, 3) arrays, for pictures; not part of :meth:`to_dict`) were kept."""

    final_error: float
    mean_error: float
    body_size: float
    steps: int
    frames: list[int] = field(default_factory=list)
    positions: Any = None
    observed: Any = None
    unstable: str = ""

    def to_dict(self) -> dict[str, Any]:
        """The numbers, JSON-ready (an infinite error as the string "inf")."""
        return {
            "final_error": _encode_float(self.final_error),
            "mean_error": _encode_float(self.mean_error),
            "body_size": self.body_size, "steps": self.steps, "unstable": self.unstable,
        }  # fmt: skip


@dataclass
class Assessment:
    """What only the task knows about a run's best solution (``Task.assess``): the ground
    truth's name and its loss when scored like a candidate, values derived from the fitted
    parameters that read better than them (``{"exp(log_E)": 4.4e5}``), and the free run."""

    truth: str = ""
    truth_loss: float | None = None
    derived: dict[str, float] = field(default_factory=dict)
    free_run: FreeRun | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "truth": self.truth, "truth_loss": self.truth_loss, "derived": self.derived,
            "free_run": None if self.free_run is None else self.free_run.to_dict(),
        }  # fmt: skip


def solution_with_parameters(task: object, solution: str, parameters: dict[str, float]) -> str:
    """``solution`` with its fitted ``parameters`` written in, where ``task`` knows how (its
    ``solution_with_parameters``); else ``solution`` unchanged."""
    write = getattr(task, "solution_with_parameters", None)
    return write(solution, parameters) if write is not None and parameters else solution


def configured(task: Any, options: dict[str, Any]) -> Any:
    """``task`` set up for ``options`` by its optional ``with_options``, else ``task``."""
    configure = getattr(task, "with_options", None)
    return configure(options) if configure is not None else task


@runtime_checkable
class Task(Protocol):
    """A scientific problem the search can work on.

    ``kind`` is ``"equation"`` (code with continuous parameters fitted by the inner loop) or
    ``"entity"`` (a structure, such as a molecule, whose continuous part is optimized).

    A task with options declares them as a class attribute ``options_type``: a dataclass whose
    fields (with defaults) are the options, typed ``int``, ``float``, ``bool``, ``str`` or a
    ``Literal`` of strings (optionally ``| None``), and whose ``__post_init__`` raises
    ``ValueError`` for a bad value. ``--option KEY=VALUE`` is checked against it before
    anything runs; ``EvaluationSettings.options`` then holds the given options, typed.

    An optional method ``check_solution(code: str) -> None`` checks the shape of a solution's
    code statically (without running it: a class with the right methods, the right literals)
    and raises :class:`sga_agent.parsing.CodeRejected`, whose message is feedback for the
    model. The search and ``sga-agent evaluate`` run it after their generic safety checks
    (:func:`sga_agent.parsing.check_candidate`), before anything is captured.

    Two optional methods warm the helper processes before their first candidate:
    ``warm_up_solutions() -> list[str]`` (captured when a capture server starts; default: the
    seed) and ``warm_up_fit(options: dict)`` (run by a fit worker once it is ready, with the
    options its evaluations will use: load data, compile kernels; it runs no candidate code).
    A ``warm_up_fit`` that returns an iterator (a generator yielding between stages) is run in
    stages, the most needed first, none starting while a candidate waits (see
    :mod:`sga_agent.fit_worker`).

    ``solution_with_parameters(solution: str, parameters: dict) -> str``, also optional,
    writes fitted parameter values into a solution for people to read (the end of a search,
    reports); it must not run the solution's code.

    ``with_options(options: dict) -> Task``, optional, returns the task set up for a run's
    options (typed, as ``EvaluationSettings.options`` holds them) where its seed, prompt or
    built-in proposer depend on them (a task whose data is a file named by an option); the
    search calls it through :func:`configured`.

    ``assess(artifacts: dict | None, parameters: dict, options: dict, simulate: bool) ->
    Assessment``, optional, tells summaries and reports what only the task knows about the
    best solution, given the artifacts its evaluation left (the captured data included), its
    fitted parameters and the run's task options: the ground truth's name and loss, readable
    derived values, and (if ``simulate``) a :class:`FreeRun`. It is trusted code: it must not
    load or run the solution's code, only what the capture recorded.
    """

    name: str
    description: str
    kind: TaskKind

    def seed_solution(self) -> str:
        """The bootstrap solution (code text) the search starts from."""
        ...

    def prompt_parts(self) -> PromptParts:
        """Task-specific prompt text."""
        ...

    def capture(self, solution: str) -> dict[str, Any]:
        """Turn ``solution`` into JSON data; runs its code, in the capture process only.

        Raises :class:`InvalidSolution` (with a one-line reason) for an unusable solution.
        """
        ...

    def evaluate(self, data: dict[str, Any], settings: EvaluationSettings) -> Evaluation:
        """Check the captured ``data`` and score it; never runs solution code, never raises
        for a bad candidate (its data is untrusted: check everything)."""
        ...


@dataclass(frozen=True)
class Parent:
    """An evaluated solution a built-in proposer may mutate or cross: its code, its loss and
    the fitted values of its continuous parameters (``Evaluation.parameters``; empty when none
    were fitted), so a child may start where its parent's inner optimization ended."""

    code: str
    loss: float
    parameters: dict[str, float] = field(default_factory=dict)


@runtime_checkable
class BuiltinProposer(Protocol):
    """An LLM-free proposer a task may offer (``task.builtin_proposer()``).

    It plays the model's part without a model: from the current top-K parents it writes ``n``
    new solutions, each an answer text holding one ```python block. ``temperature`` is the
    search's exploit (low) or explore (high) temperature: low means small changes to good
    parents, high means bolder ones. Everything random derives from ``seed``, so a call with
    the same arguments returns the same answers.
    """

    name: str

    def propose_from(
        self, parents: Sequence[Parent], temperature: float, n: int, seed: int
    ) -> list[str]: ...
