"""Assembling a search from its config: task, proposer, evaluation pool, run store.

Shared by ``sga-agent search`` and ``sga-agent resume`` (and usable from Python). A process
resolves its task once (``registry.load_task``) and hands it on: the task's options are read
from text once (:func:`task_options`), and the task is set up for them once
(:func:`~sga_agent.task.configured`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import sys
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from sga_agent import registry
from sga_agent.config import SearchConfig
from sga_agent.events import SandboxReady
from sga_agent.options import parse_options
from sga_agent.proposers.base import Proposer
from sga_agent.proposers.builtin import BuiltinAdapter
from sga_agent.proposers.replay import ReplayProposer
from sga_agent.ray_executor import RayPool
from sga_agent.run_store import RunStore
from sga_agent.sandbox import SandboxPool, threads_per_worker
from sga_agent.search import Search, SearchResult
from sga_agent.task import Task, TaskBase, as_task, configured

REPLAY_PREFIX = "replay:"
BUILTIN = "builtin"


class ProposerChoiceError(ValueError):
    """The requested proposer does not exist for this task."""


def is_builtin(proposer: str) -> bool:
    """Whether ``proposer`` names the task's built-in proposer ("builtin", "builtin:gp")."""
    return proposer == BUILTIN or proposer.startswith(BUILTIN + ":")


def task_options(task: TaskBase, raw: Mapping[str, str], proposer: str) -> Any:
    """The run's options object, read once from ``raw`` (``--option`` texts), which win over
    the task's :attr:`~sga_agent.task.TaskBase.builtin_options` when ``proposer`` is its
    built-in one (the constitutive GP's ``optimizer=lbfgs``).

    Raises
    ------
    sga_agent.options.OptionError
        An unknown option, or a value the task refuses.
    """
    given = {**task.builtin_options, **raw} if is_builtin(proposer) else dict(raw)
    return parse_options(task.options_type, given, task.name)


def make_proposer(config: SearchConfig, task: Task) -> Proposer:
    """The proposer ``config.proposer`` names: a litellm model, the task's built-in
    (LLM-free) proposer ("builtin" or its name, e.g. "builtin:gp"), or the answers of a
    recorded run ("replay:RUN_DIR").

    Raises
    ------
    ProposerChoiceError
        The task has no such built-in proposer.
    sga_agent.run_store.RunStoreError
        The replayed folder is not a run folder.
    """
    if config.proposer.startswith(REPLAY_PREFIX):
        return ReplayProposer(Path(config.proposer[len(REPLAY_PREFIX) :]))
    if is_builtin(config.proposer):
        builtin = as_task(task).builtin_proposer()
        if builtin is None:
            raise ProposerChoiceError(f"task {task.name!r} has no built-in proposer; use --model")
        if config.proposer not in (BUILTIN, builtin.name):
            raise ProposerChoiceError(
                f"task {task.name!r} offers {builtin.name!r}, not {config.proposer!r}"
            )
        return BuiltinAdapter(builtin)
    from sga_agent.proposers.litellm_backbone import BackboneSettings, LiteLLMProposer

    model = config.model
    return LiteLLMProposer(
        BackboneSettings(
            model=config.proposer,
            api_base=config.api_base,
            timeout_s=model.request_timeout_s,
            max_retries=model.retries,
            price_per_million=model.price,
        )
    )


def replayed_answers(config: SearchConfig) -> dict[str, dict[str, Any]]:
    """Recorded answers of the run a ``replay:RUN_DIR`` proposer names (empty for another
    proposer); raises :class:`~sga_agent.run_store.RunStoreError` for a bad folder."""
    if not config.proposer.startswith(REPLAY_PREFIX):
        return {}
    return ReplayProposer(Path(config.proposer[len(REPLAY_PREFIX) :])).answers


def make_pool(config: SearchConfig) -> SandboxPool | RayPool:
    """The evaluation pool ``config.executor`` names: local processes, or Ray tasks.

    Raises
    ------
    sga_agent.ray_executor.RayUnavailableError
        The ray executor without Ray installed, or with no cluster at its ``ray_address``.
    """
    executor = config.executor
    if executor.kind == "local":
        limits = config.sandbox.limits(threads_per_worker(executor.workers))
        return SandboxPool(max_workers=executor.workers, limits=limits)
    # the CPUs a Ray slot reserves are the threads of its fit's parallel loops
    limits = config.sandbox.limits(max(1, math.floor(executor.ray_cpus_per_task)))
    return RayPool(
        executor.ray_address,
        limits,
        cpus_per_task=executor.ray_cpus_per_task,
        memory_mb=executor.ray_memory_mb,
        local_cpus=math.ceil(executor.workers * executor.ray_cpus_per_task),
    )


def pool_record(pool: SandboxPool | RayPool) -> SandboxReady:
    """The run's sandbox event: how workers are isolated and where they run."""
    if isinstance(pool, RayPool):
        where = pool.describe()
    else:
        where = {"executor": "local", "workers": pool.max_workers}
    return SandboxReady(dataclasses.asdict(pool.isolation()), where)


def run(
    config: SearchConfig,
    store: RunStore,
    on_event: Callable[[dict[str, Any]], None] | None = None,
    proposer: Proposer | None = None,
    task: Task | None = None,
    started: float | None = None,
) -> SearchResult:
    """Run (or continue) the search ``config`` describes, recording into ``store``. ``task``
    is the run's task set up for its options (:func:`~sga_agent.task.configured`), resolved
    from ``config.task`` unless given; the proposer is ``make_proposer``'s unless given.
    ``started`` is the :func:`time.monotonic` instant the session's wall time counts from
    (default: the search's start; the ``sga-agent`` program counts from its process's start)."""
    if task is None:
        task = configured(registry.load_task(config.task), config.task_options)
    if proposer is None:
        proposer = make_proposer(config, task)
    store.record_provenance(as_task(task).provenance(config.task_options))
    with make_pool(config) as pool:
        store.append(pool_record(pool))
        search = Search(config, task, proposer, pool, store, on_event, started)
        result = search.run()
    budgets = config.budgets
    spent = budgets.exceeded(result.totals, ("max_seconds",), kept=budgets.kept_for_end())
    record_findings(store, task, config.task_options, compare=not spent)
    return result


def record_findings(store: RunStore, task: Task, options: Any, compare: bool = True) -> None:
    """Complete the run's ``summary.json`` with what it found (:mod:`sga_agent.report.findings`):
    the best loss against the seed's and the true law's, the best solution with its fitted
    constants, the task's assessment with the run's ``options`` object (its free run, for
    instance), and with ``compare`` (False once a time budget is spent, so that the budget
    holds) the comparison of the forms that fit equally and the simplified best. Read back
    from the run folder, as the report does; the search core knows nothing of it."""
    from sga_agent.report.data import read_run
    from sga_agent.report.findings import find

    with contextlib.redirect_stdout(sys.stderr):  # stdout may carry --json (Taichi prints)
        findings = find(read_run(store.path), task, options, compare=compare).to_dict()
    store.save_summary({**store.summary(), "findings": findings})
