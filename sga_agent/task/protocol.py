"""The contract itself: what a task must provide (:class:`Task`), every hook it may provide
with its default (:class:`TaskBase`), and the proposer it may offer (:class:`BuiltinProposer`).

The agent reaches a task only through :func:`as_task` (the registry applies it), so it calls
every hook without asking whether the task has it. Standard library only (part of the
protocol package :mod:`sga_agent.task`).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from types import MappingProxyType
from typing import Any, ClassVar, Protocol, runtime_checkable

from sga_agent.task.forms import FormComparison
from sga_agent.task.records import (
    Assessment,
    Evaluation,
    EvaluationSettings,
    NoOptions,
    Parent,
    PromptParts,
    Simplified,
    TaskKind,
)
from sga_agent.task.report import Block, CandidateRecord, ReportView, Section


@runtime_checkable
class Task(Protocol):
    """What every task provides: a scientific problem the search can work on.

    ``kind`` is ``"equation"`` (code with continuous parameters fitted by the inner loop) or
    ``"entity"`` (a structure, such as a molecule, whose continuous part is optimized).
    ``name`` is the registry name, ``description`` one line for ``sga-agent tasks``.
    The optional hooks are those of :class:`TaskBase`.
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

        Raises :class:`~sga_agent.task.InvalidSolution` (with a one-line reason) for an
        unusable solution.
        """
        ...

    def evaluate(self, data: dict[str, Any], settings: EvaluationSettings) -> Evaluation:
        """Check the captured ``data`` and score it; never runs solution code, never raises
        for a bad candidate (its data is untrusted: check everything).

        Optional: as its fit goes it may call :func:`~sga_agent.task.report_progress` (a stage
        starting, each epoch finished with its loss), which a fit worker passes on to the
        progress display of ``sga-agent evaluate`` and of the search; informational only,
        and a no-op where nobody listens. A task that never calls it works as well.
        """
        ...


@runtime_checkable
class BuiltinProposer(Protocol):
    """An LLM-free proposer a task may offer (:meth:`TaskBase.builtin_proposer`).

    It plays the model's part without a model: from the current top-K parents it writes ``n``
    new solutions, each an answer text holding one ```python block. ``temperature`` is the
    search's exploit (low) or explore (high) temperature: low means small changes to good
    parents, high means bolder ones. Everything random derives from ``seed``, so a call with
    the same arguments returns the same answers. A proposer whose ``propose_from`` also takes
    a keyword ``tried`` is given the answer texts of every earlier proposal of the run (oldest
    first), so it can avoid what was already evaluated; one that takes a keyword ``opening``
    is told whether the batch is the search's wide first look (``--opening``), which it may
    answer with a list of likely solutions; one without them works as before. The task
    options it is meant to run with are the task's :attr:`TaskBase.builtin_options`.
    """

    name: str

    def propose_from(
        self, parents: Sequence[Parent], temperature: float, n: int, seed: int
    ) -> list[str]: ...


class TaskBase:
    """A task's optional hooks, each with its default: subclass it and override what applies.

    A subclass still provides what :class:`Task` requires (``name``, ``description``,
    ``kind``, ``seed_solution``, ``prompt_parts``, ``capture``, ``evaluate``). A plugin that
    does not subclass it is wrapped by :func:`as_task`, which gives it these defaults.
    """

    name: str
    description: str
    kind: TaskKind

    #: The options' dataclass: fields with defaults typed ``int``, ``float``, ``bool``, ``str``
    #: or a ``Literal`` of strings (optionally ``| None``), whose ``__post_init__`` raises
    #: ``ValueError`` for a bad value. ``--option KEY=VALUE`` is read into one object of it
    #: before anything runs; that object is what ``EvaluationSettings.options``,
    #: :meth:`with_options`, :meth:`warm_up_fit` and :meth:`assess` are given (in a fit worker,
    #: built again once from its JSON: its values must survive JSON).
    options_type: ClassVar[type] = NoOptions
    #: Options a run whose proposer is this task's built-in one uses unless it sets them
    #: itself, as ``--option`` texts (``{"optimizer": "lbfgs"}``). Default: none.
    builtin_options: ClassVar[Mapping[str, str]] = MappingProxyType({})
    #: Whether :meth:`evaluate` honours ``EvaluationSettings.fidelity`` below 1 with a cheaper
    #: fit. The ``quick`` preset then screens its candidates (``--fidelity multi``) unless the
    #: command says otherwise or gives a time budget. Default: False (a screen costs a full fit).
    screens_cheaply: ClassVar[bool] = False
    #: The share of a full fit each screen of the ``quick`` preset's opening takes (its wide
    #: first iteration, with this task's built-in proposer, where it screens cheaply): the
    #: least that ranks the task's solutions as their full fits rank them. Default: 0.1.
    opening_screen: ClassVar[float] = 0.1
    #: How many answers that opening asks of the built-in proposer (its most likely
    #: solutions, screened together). Default: 40.
    opening_answers: ClassVar[int] = 40
    #: Modules the capture server imports once, before it confines any capture (torch, the
    #: task's own capture module): a confined capture may be unable to import them.
    capture_modules: ClassVar[tuple[str, ...]] = ()
    #: What a loss is, for the report's axes ("loss: mean squared position error (m²)").
    loss_label: ClassVar[str] = "loss"
    #: What :meth:`solution_size` counts, for the report ("operations of the captured law").
    size_label: ClassVar[str] = "size"

    # ------------------------------------------------------------------ solutions

    def check_solution(self, code: str) -> None:
        """Check the shape of a solution's code statically (without running it: a class with
        the right methods, the right literals); raise
        :class:`~sga_agent.task.CodeRejected`, whose message is feedback for the model.

        The search and ``sga-agent evaluate`` run it after their generic safety checks
        (:func:`sga_agent.parsing.check_candidate`), before anything is captured; code that
        does not parse is not shown to it. Default: any code is accepted.
        """

    def solution_with_parameters(self, solution: str, parameters: dict[str, float]) -> str:
        """``solution`` with its fitted ``parameters`` written in, for people to read (the end
        of a search, reports); it must not run the solution's code. Default: unchanged."""
        return solution

    def formula(self, solution: str, parameters: dict[str, float]) -> str:
        """``solution`` as one formula with its fitted ``parameters`` in, for people to read
        beside its code (a genetic-programming law: ``F_corrected = 0.31*F + ...``), where
        the task can write one; it must not run the solution's code. Default: "" (none)."""
        return ""

    def parameter_units(self, solution: str, names: Sequence[str]) -> dict[str, str]:
        """The units of the quantities ``names`` stand for in ``solution``, by name, for people
        to read (``sga-agent evaluate``, the end of a search): ``{"friction_angle": "deg"}``.
        A name is a parameter's natural name (``friction_angle`` for ``log_friction_angle``,
        shown as its exp: :mod:`sga_agent.natural_units`); one left out is shown without a
        unit. It must not run the solution's code. Default: {} (no unit known)."""
        return {}

    def with_options(self, options: Any) -> TaskBase:
        """The task set up for a run's ``options`` (an :attr:`options_type` object) where its
        seed, prompt or built-in proposer depend on them (a task whose data is a file named by
        an option). Default: the task itself."""
        return self

    def builtin_proposer(self) -> BuiltinProposer | None:
        """An LLM-free proposer (``--proposer builtin``); default: None, the task has none."""
        return None

    # ------------------------------------------------------------------ helper processes

    def warm_up_solutions(self) -> list[str]:
        """Solutions a capture server captures when it starts, so that later captures find
        everything loaded. Default: the seed."""
        return [self.seed_solution()]

    def warm_up_fit(self, options: Any) -> Iterator[None] | None:
        """Run by a fit worker once it is ready, with the options (an :attr:`options_type`
        object) its evaluations will use: load data, compile kernels; it runs no candidate
        code. An iterator (a generator yielding between stages) is run in stages, the most
        needed first, none starting while a candidate waits (see :mod:`sga_agent.fit_worker`).
        It may report its stages (:func:`~sga_agent.task.report_progress`), as ``evaluate``
        may. Default: nothing to warm."""
        return None

    # ------------------------------------------------------------------ findings

    def provenance(self, options: Any) -> dict[str, Any]:
        """What a run with ``options`` is measured against, as JSON data recorded in the run
        folder (``provenance.json``) when its search starts: the observation file's sha256,
        the truth it read. A report compares it with what the task gives then, says what
        changed, and hands the recorded one to :meth:`with_provenance`. Default: {} (nothing
        to record)."""
        return {}

    def with_provenance(self, recorded: Mapping[str, Any]) -> TaskBase:
        """The task set up to assess a run that recorded ``recorded`` (what :meth:`provenance`
        returned when it started), so that :meth:`assess` names the truth the run was measured
        against even when the files have changed since. Default: the task itself."""
        return self

    def assess(
        self,
        artifacts: dict[str, Any] | None,
        parameters: dict[str, float],
        options: Any,
        simulate: bool,
    ) -> Assessment | None:
        """What only the task knows about a run's best solution, given the artifacts its
        evaluation left (the captured data included), its fitted parameters and the run's task
        options (an :attr:`options_type` object): the ground truth's name and loss, readable
        derived values and (if ``simulate``) a free run. Trusted code: it must not load or run
        the solution's code, only what the capture recorded. Default: None, nothing to add."""
        return None

    def compare_forms(
        self, candidates: Sequence[CandidateRecord], options: Any, folder: Path | None
    ) -> FormComparison | None:
        """Whether the data determine the best solution's form (:mod:`sga_agent.task.forms`),
        given the run's best distinct candidates (best first) and its task options: the forms
        that fit within the task's noise (:func:`~sga_agent.task.forms.within_noise`) run on
        probe scenes the task defines (never its held-out scene), their spread measured
        (:func:`~sga_agent.task.forms.compared`); the separating probe's scene may be written
        into ``folder`` (the run folder; None: write nothing). Called after :meth:`assess`
        with ``simulate``; trusted code, as :meth:`assess`. Default: None, the task cannot
        tell."""
        return None

    def simplify(self, candidate: CandidateRecord, options: Any) -> Simplified | None:
        """The run's best solution (``candidate``) with the parts the data do not need dropped:
        those whose removal, nothing refitted, keeps its loss within the task's noise
        (:func:`~sga_agent.task.forms.within_noise`); None when nothing can go. Called after
        :meth:`assess` with ``simulate``; trusted code: it must not run the solution's code.
        Default: None, not simplified."""
        return None

    def describe_assessment(self, simulate: bool) -> str:
        """What :meth:`assess` is about to do, told to the reader before it starts when it may
        take a while; default: "" (nothing to tell)."""
        return ""

    def solution_key(self, candidate: CandidateRecord) -> str | None:
        """What makes two recorded candidates the same solution when the report picks the
        top distinct ones (a molecule's SMILES). Default: None, the code with its fitted
        parameters' starting values set to 0."""
        return None

    def solution_size(self, candidate: CandidateRecord) -> int | None:
        """How large a recorded candidate's solution is, in the unit :attr:`size_label` names
        (the operations of a captured law), for the report's loss-versus-size front; from what
        the capture recorded, never by running its code. Default: None, no front."""
        return None

    def top_facts(self, candidates: Sequence[CandidateRecord]) -> list[dict[str, Any]]:
        """JSON facts about the run's best distinct candidates (best first), for
        ``summary.json`` and the report; the molecule tasks give each molecule's property in
        Hartree and eV. Default: none."""
        return []

    # ------------------------------------------------------------------ report

    def screen_lines(self, findings: dict[str, Any]) -> list[str]:
        """Lines for the end of a search's screen, after the best loss and the ground truth,
        from ``summary.json``'s ``findings`` (a free run's error). Default: none."""
        return []

    def summary_lines(self, view: ReportView) -> list[str]:
        """Lines (``- ...``) added to the report summary's list after the losses (a free run's
        error). Default: none."""
        return []

    def summary_blocks(self, view: ReportView) -> list[Block]:
        """Blocks shown under the report summary's list in place of the best solution's code
        (a table of the top molecules). Default: none, the code is shown."""
        return []

    def report_sections(self, view: ReportView) -> list[Section]:
        """Sections placed after the report's summary (the task's own pictures, drawn into
        ``view.folder``); a failure should become a note, not an exception. Default: none."""
        return []


#: What :class:`Task` requires, and the hooks of :class:`TaskBase`.
REQUIRED = ("name", "description", "kind", "seed_solution", "prompt_parts", "capture", "evaluate")
HOOKS = tuple(name for name in vars(TaskBase) if not name.startswith("_"))


class _Adapted(TaskBase):
    """A plugin that does not subclass :class:`TaskBase`: its own members, else the defaults.
    With :func:`has_hook`, the one place that looks at which hooks a plugin has."""

    def __init__(self, plugin: Task) -> None:
        self.plugin = plugin
        for member in (*REQUIRED, *HOOKS):
            if hasattr(plugin, member):
                setattr(self, member, getattr(plugin, member))

    def __repr__(self) -> str:
        return repr(self.plugin)


def has_hook(task: TaskBase, name: str) -> bool:
    """Whether ``task`` (a :class:`TaskBase`, or a plugin through :func:`as_task`) has hook
    ``name`` of its own rather than :class:`TaskBase`'s default."""
    return getattr(getattr(task, name), "__func__", None) is not getattr(TaskBase, name)


def as_task(task: Task) -> TaskBase:
    """``task`` with every hook of :class:`TaskBase`: itself when it subclasses it, else
    wrapped so that the hooks it lacks take their defaults."""
    return task if isinstance(task, TaskBase) else _Adapted(task)


def options_type(task: Task) -> type:
    """The dataclass of ``task``'s options (:attr:`TaskBase.options_type`)."""
    return as_task(task).options_type


def solution_with_parameters(task: Task | None, solution: str, parameters: dict[str, float]) -> str:
    """``solution`` with its fitted ``parameters`` written in by ``task``
    (:meth:`TaskBase.solution_with_parameters`); unchanged without a task or parameters."""
    if task is None or not parameters:
        return solution
    return as_task(task).solution_with_parameters(solution, parameters)


def configured(task: Task, options: Any) -> TaskBase:
    """``task`` set up for ``options`` (:meth:`TaskBase.with_options`)."""
    return as_task(as_task(task).with_options(options))
