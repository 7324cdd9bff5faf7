"""A conformance check any task plugin can run in its own tests: :func:`check_task`.

It checks what :class:`sga_agent.task.Task` requires and every optional hook of
:class:`sga_agent.task.TaskBase` (its default or the task's own), the way the agent will call
them::

    from sga_agent.testing import check_task

    def test_my_task_keeps_the_contract():
        check_task(MyTask())

The seed solution goes through the generic and the task's own static checks and is captured
(in this process: the check trusts the task's own seed); with ``evaluate=True`` (the default)
its captured data is also scored with ``settings``. Everything the agent stores must survive
JSON. The problems found are reported together, one line each.
"""

from __future__ import annotations

import dataclasses
import difflib
import json
import math
import tempfile
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sga_agent.options import describe_options, options_from_data, options_json, typed_values
from sga_agent.parsing import check_candidate, parse_response
from sga_agent.task import (
    Assessment,
    BuiltinProposer,
    CodeRejected,
    Evaluation,
    EvaluationSettings,
    Parent,
    PromptParts,
    ReportView,
    Section,
    Task,
    TaskBase,
    as_task,
    configured,
)
from sga_agent.task.protocol import HOOKS, REQUIRED

KINDS = ("equation", "entity")


class ContractError(AssertionError):
    """The task breaks its contract; the message lists each problem on a line."""


def check_task(
    task: Task,
    options: dict[str, Any] | None = None,
    evaluate: bool = True,
    settings: EvaluationSettings | None = None,
) -> None:
    """Check ``task`` against the plugin contract.

    Parameters
    ----------
    task : Task
        The task object, as its entry point makes it.
    options : dict, optional
        Task options (typed values) the checks run with, as a run's ``--option`` values give
        them: needed where the task has options without a default. They are built into the
        task's options object, which must survive JSON (a fit worker builds it from that),
        and the task is set up for it with ``with_options`` first.
    evaluate : bool
        Also score the captured seed (a real evaluation: as slow as the task's fit).
    settings : EvaluationSettings, optional
        For that evaluation; default: no inner optimization (``epochs=0``), those options.

    Raises
    ------
    ContractError
        The problems found, one line each.
    """
    problems: list[str] = []
    if not isinstance(task, Task):
        missing = [name for name in REQUIRED if not hasattr(task, name)]
        raise ContractError(f"{type(task).__name__} lacks {', '.join(missing)} (required)")
    base = as_task(task)
    built = _collect(problems, "options", lambda: _options(base, dict(options or {})))
    full = base if built is None else configured(base, built)
    for check in (_identity, _misspelt_hooks, _prompt, _warm_up, _report_hooks):
        _collect(problems, check.__name__, lambda c=check: c(task, full))
    data = _collect(problems, "the seed", lambda: _seed(full))
    if evaluate and data is not None:
        settings = settings or EvaluationSettings(epochs=0, options=built)
        _collect(problems, "evaluate", lambda: _evaluation(full, data, settings))
    _collect(problems, "builtin_proposer", lambda: _builtin(full))
    if problems:
        name = task.name if hasattr(task, "name") else "?"
        raise ContractError(f"task {name!r}:\n- " + "\n- ".join(problems))


def _collect(problems: list[str], where: str, check: Callable[[], Any]) -> Any:
    """Run ``check``; what it says is wrong (or raises) is added to ``problems``."""
    try:
        result = check()
    except ContractError as error:
        problems.extend(str(error).splitlines())
        return None
    except Exception as error:
        problems.append(f"{where.strip('_')}: raised {type(error).__name__}: {error}")
        return None
    return result


def _expect(condition: bool, problem: str) -> None:
    if not condition:
        raise ContractError(problem)


def _identity(task: Task, full: TaskBase) -> None:
    _expect(isinstance(task.name, str) and bool(task.name), "name must be a non-empty str")
    _expect(isinstance(task.description, str), "description must be a str")
    _expect(task.kind in KINDS, f"kind must be one of {KINDS}, got {task.kind!r}")


def _misspelt_hooks(task: Task, full: TaskBase) -> None:
    """A public member named almost like a hook is probably that hook, misspelt."""
    known = (*REQUIRED, *HOOKS)
    for name in dir(task):
        if name.startswith("_") or name in known:
            continue
        close = difflib.get_close_matches(name, known, n=1, cutoff=0.85)
        if close:
            raise ContractError(f"{name!r} is no hook of the contract; did you mean {close[0]!r}?")


def _options(full: TaskBase, options: dict[str, Any]) -> Any:
    """The options object of ``options`` (the rest by default), once its type is checked."""
    kind = full.options_type
    _expect(dataclasses.is_dataclass(kind), "options_type must be a dataclass")
    describe_options(kind)  # every field's type is one options can be read as
    hints = typing.get_type_hints(kind)
    for field in dataclasses.fields(kind):
        _expect(field.name in hints, f"option {field.name!r} has no type")
    built = options_from_data(kind, options, full.name)
    sent = options_from_data(kind, json.loads(options_json(built)), full.name)
    _expect(sent == built, "the options must survive JSON unchanged (a fit worker gets them so)")
    preferred = full.builtin_options
    _expect(all(isinstance(text, str) for text in preferred.values()),
            "builtin_options must map option names to texts, as --option takes them")  # fmt: skip
    preferred_values = typed_values(kind, preferred, full.name)  # options it has, values they take
    dataclasses.replace(built, **preferred_values)  # and its checks accept
    _expect(isinstance(full.with_options(built), Task), "with_options must return a task")
    _expect(
        isinstance(full.capture_modules, tuple)
        and all(isinstance(m, str) for m in full.capture_modules),
        "capture_modules must be a tuple of module names",
    )
    return built


def _prompt(task: Task, full: TaskBase) -> None:
    parts = full.prompt_parts()
    _expect(isinstance(parts, PromptParts), "prompt_parts must return a PromptParts")
    for field in dataclasses.fields(PromptParts):
        _expect(isinstance(getattr(parts, field.name), str), f"prompt_parts().{field.name}: str")
    _expect(isinstance(full.loss_label, str) and bool(full.loss_label), "loss_label: a str")


def _warm_up(task: Task, full: TaskBase) -> None:
    solutions = full.warm_up_solutions()
    _expect(
        isinstance(solutions, list) and all(isinstance(s, str) for s in solutions),
        "warm_up_solutions must return a list of str",
    )


def _seed(full: TaskBase) -> dict[str, Any]:
    seed = full.seed_solution()
    _expect(isinstance(seed, str) and bool(seed.strip()), "seed_solution must return code text")
    try:
        check_candidate(seed, full)
    except CodeRejected as error:
        raise ContractError(f"the seed fails the static checks: {error}") from None
    shown = full.solution_with_parameters(seed, {})
    _expect(isinstance(shown, str), "solution_with_parameters must return a str")
    data = full.capture(seed)
    _expect(isinstance(data, dict), "capture must return a dict")
    _expect(json.loads(json.dumps(data)) == data, "capture's data must survive JSON unchanged")
    return data


def _evaluation(full: TaskBase, data: dict[str, Any], settings: EvaluationSettings):
    result = full.evaluate(data, settings)
    _expect(isinstance(result, Evaluation), "evaluate must return an Evaluation")
    _expect(result.valid, f"the seed must score: {result.reason}")
    _expect(not math.isnan(result.loss), "the seed's loss is NaN")
    json.dumps(result.to_dict())  # what the run store writes
    nothing = full.evaluate({}, settings)
    _expect(isinstance(nothing, Evaluation) and not nothing.valid,
            "evaluate({}) must return an invalid Evaluation, not raise")  # fmt: skip


def _builtin(full: TaskBase) -> None:
    proposer = full.builtin_proposer()
    if proposer is None:
        return
    _expect(isinstance(proposer, BuiltinProposer), "builtin_proposer must be a BuiltinProposer")
    parents = [Parent(full.seed_solution(), 1.0)]
    answers = proposer.propose_from(parents, 0.5, 2, seed=0)
    _expect(answers == proposer.propose_from(parents, 0.5, 2, seed=0),
            "the built-in proposer must answer alike for the same seed")  # fmt: skip
    for answer in answers:
        _expect(parse_response(answer).code is not None,
                "each built-in answer must hold one ```python block")  # fmt: skip


@dataclasses.dataclass
class _Recorded:
    """A candidate as the report reads it back, recorded without extras or parameters."""

    code: str
    id: str = "00-seed"
    status: str = "ok"
    loss: float = 1.0
    parameters: dict[str, float] = dataclasses.field(default_factory=dict)
    extras: dict[str, Any] = dataclasses.field(default_factory=dict)

    def artifacts(self) -> dict[str, Any]:
        return {}


def _report_hooks(task: Task, full: TaskBase) -> None:
    for simulate in (True, False):
        _expect(isinstance(full.describe_assessment(simulate), str), "describe_assessment: str")
    _expect(full.top_facts([]) == [], "top_facts([]) must be []")
    nothing = _Recorded(full.seed_solution())
    key = full.solution_key(nothing)
    _expect(key is None or isinstance(key, str), "solution_key must return a str or None")
    _expect(isinstance(full.screen_lines({}), list), "screen_lines must return a list")
    with tempfile.TemporaryDirectory() as folder:  # a run that scored nothing
        view = ReportView(task.name, None, [], Assessment(), Path(folder), False)
        _expect(all(isinstance(line, str) for line in full.summary_lines(view)),
                "summary_lines must return str lines")  # fmt: skip
        _expect(isinstance(full.summary_blocks(view), list), "summary_blocks must return a list")
        sections = full.report_sections(view)
        _expect(all(isinstance(s, Section) for s in sections),
                "report_sections must return Sections")  # fmt: skip
