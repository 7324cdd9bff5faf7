"""Assembling a search from its config: task, proposer, evaluation pool, run store.

Shared by ``sga-agent search`` and ``sga-agent resume`` (and usable from Python).
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sga_agent import registry
from sga_agent.config import SearchConfig
from sga_agent.events import SandboxReady
from sga_agent.proposers.base import Proposer
from sga_agent.proposers.builtin import BuiltinAdapter
from sga_agent.proposers.replay import ReplayProposer
from sga_agent.ray_executor import RayPool
from sga_agent.run_store import RunStore
from sga_agent.sandbox import SandboxLimits, SandboxPool, threads_per_worker
from sga_agent.search import Search, SearchResult
from sga_agent.task import Task, as_task, configured

REPLAY_PREFIX = "replay:"
BUILTIN = "builtin"


class ProposerChoiceError(ValueError):
    """The requested proposer does not exist for this task."""


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
    if config.proposer == BUILTIN or config.proposer.startswith(BUILTIN + ":"):
        builtin = as_task(task).builtin_proposer()
        if builtin is None:
            raise ProposerChoiceError(f"task {task.name!r} has no built-in proposer; use --model")
        if config.proposer not in (BUILTIN, builtin.name):
            raise ProposerChoiceError(
                f"task {task.name!r} offers {builtin.name!r}, not {config.proposer!r}"
            )
        return BuiltinAdapter(builtin)
    from sga_agent.proposers.litellm_backbone import BackboneSettings, LiteLLMProposer

    return LiteLLMProposer(BackboneSettings(model=config.proposer, api_base=config.api_base))


def with_preferred_options(config: SearchConfig, proposer: Proposer) -> SearchConfig:
    """``config`` with the task options a built-in proposer is meant to run with (its
    ``task_options``, e.g. the constitutive GP's ``{"optimizer": "lbfgs"}``) added; options
    the config sets already win."""
    preferred = getattr(proposer, "task_options", None)
    if not preferred:
        return config
    return dataclasses.replace(config, task_options={**preferred, **config.task_options})


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
        The ray executor without Ray installed, or with no cluster at ``config.ray_address``.
    """
    if config.executor == "local":
        threads = threads_per_worker(config.workers)
    else:  # the CPUs a Ray slot reserves are the threads of its fit's parallel loops
        threads = max(1, math.floor(config.ray_cpus_per_task))
    limits = SandboxLimits(timeout_s=config.timeout_s, memory_mb=config.memory_mb,
                           threads=threads)  # fmt: skip
    if config.executor == "local":
        return SandboxPool(max_workers=config.workers, limits=limits)
    return RayPool(
        config.ray_address,
        limits,
        cpus_per_task=config.ray_cpus_per_task,
        memory_mb=config.ray_memory_mb,
        local_cpus=math.ceil(config.workers * config.ray_cpus_per_task),
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
) -> SearchResult:
    """Run (or continue) the search ``config`` describes, recording into ``store``; the
    proposer is ``make_proposer``'s unless given."""
    task = configured(registry.load_task(config.task), config.task_options)
    if proposer is None:
        proposer = make_proposer(config, task)
    with make_pool(config) as pool:
        store.append(pool_record(pool))
        search = Search(config, task, proposer, pool, store, on_event)
        result = search.run()
    record_findings(store, task)
    return result


def record_findings(store: RunStore, task: Task) -> None:
    """Complete the run's ``summary.json`` with what it found (:mod:`sga_agent.report.findings`):
    the best loss against the seed's and the true law's, the best solution with its fitted
    constants, the task's assessment (its free run, for instance). Read back from the run
    folder, as the report does; the search core knows nothing of it."""
    from sga_agent.report.data import read_run
    from sga_agent.report.findings import find

    with contextlib.redirect_stdout(sys.stderr):  # stdout may carry --json (Taichi prints)
        findings = find(read_run(store.path), task).to_dict()
    store.save_summary({**store.summary(), "findings": findings})
