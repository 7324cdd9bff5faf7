"""Settings of one search run, and the presets that reproduce the paper's Table 1 columns.

A run is fully described by a :class:`SearchConfig`; it is written to the run folder, so
``sga-agent resume`` continues with exactly the same settings.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import os
import re
from dataclasses import dataclass, field
from typing import Any

from sga_agent.sandbox import SandboxLimits

#: Iterations, top-K shown, exploit/explore offspring per iteration, bilevel on or off. All but
#: "quick" are the columns of the paper's Table 1; "quick" is the default of the LLM-free
#: built-in proposers: a short run (25 candidates, 5 inner epochs) that shows the pipeline.
PRESETS: dict[str, dict[str, Any]] = {
    "quick": {
        "iterations": 4, "top_k": 5, "exploit": 2, "explore": 4, "bilevel": True, "epochs": 5,
    },
    "sga": {"iterations": 5, "top_k": 5, "exploit": 4, "explore": 12, "bilevel": True},
    "no-bilevel": {"iterations": 5, "top_k": 5, "exploit": 4, "explore": 12, "bilevel": False},
    "no-exploit": {"iterations": 5, "top_k": 5, "exploit": 0, "explore": 16, "bilevel": True},
    "cot": {"iterations": 1, "top_k": 5, "exploit": 1, "explore": 0, "bilevel": False},
    "funsearch": {"iterations": 20, "top_k": 2, "exploit": 0, "explore": 4, "bilevel": False},
    "eureka": {"iterations": 5, "top_k": 1, "exploit": 0, "explore": 16, "bilevel": False},
    "opro": {"iterations": 5, "top_k": 5, "exploit": 0, "explore": 16, "bilevel": False},
}


#: Where candidates are evaluated: this machine's process pool, or a Ray cluster.
EXECUTORS = ("local", "ray")
#: A Ray head node's GCS address, HOST:PORT (the port ``ray start --head`` printed).
_RAY_ADDRESS = re.compile(r"^[A-Za-z0-9._-]+:\d{1,5}$")


class ConfigError(ValueError):
    """A search setting is invalid; the message names it and the fix."""


@dataclass(frozen=True)
class SearchConfig:
    """Everything that determines a search run.

    Parameters
    ----------
    task : str
        Registered task name (``sga-agent tasks``).
    proposer : str
        Who proposes: a litellm model string ("openai/gpt-4o"), or "replay:RUN_DIR".
    api_base : str, optional
        Base URL of an OpenAI-compatible server (local models).
    iterations, top_k, exploit, explore : int
        Outer iterations; solutions shown per prompt (K); offspring per iteration asked at the
        exploit (low) and explore (high) temperature (M_l, M_h).
    exploit_temperature, explore_temperature : float
        T_l and T_h (paper: 0.5 and 1.0).
    bilevel : bool
        Fit each candidate's continuous parameters (off: evaluate the defaults as proposed).
    epochs, learning_rate : optional
        Inner optimization overrides (default: the task's).
    task_options : dict
        Task-specific evaluation options (e.g. ``{"steps": 200}`` for a short scene).
    workers : int
        Candidates evaluated at once, each in its own sandboxed process (with the ``ray``
        executor: the size of the local Ray instance started when no address is given).
    timeout_s, memory_mb : limits of one evaluation.
    executor : str
        "local" (a pool of sandboxed processes on this machine) or "ray" (each evaluation a
        Ray task running the same sandboxed worker on a node of a Ray cluster).
    ray_address : str, optional
        The Ray cluster: "HOST:PORT" of its head node, or "auto" (``RAY_ADDRESS``, else a
        cluster started on this machine with ``ray start``); None starts a private local Ray
        instance for the run.
    ray_cpus_per_task, ray_memory_mb : optional
        Ray resources each evaluation reserves: CPUs, and memory in MiB (None: none).
    max_usd, max_tokens, max_evaluations : optional budgets; the run stops cleanly at them.
    seed : int
        Seed passed to the evaluations and the offline proposers.
    """

    task: str
    proposer: str
    api_base: str | None = None
    preset: str = "sga"
    iterations: int = 5
    top_k: int = 5
    exploit: int = 4
    explore: int = 12
    exploit_temperature: float = 0.5
    explore_temperature: float = 1.0
    bilevel: bool = True
    epochs: int | None = None
    learning_rate: float | None = None
    task_options: dict[str, Any] = field(default_factory=dict)
    workers: int = field(default_factory=lambda: os.cpu_count() or 1)
    timeout_s: float = SandboxLimits.timeout_s
    memory_mb: int = SandboxLimits.memory_mb
    max_usd: float | None = None
    max_tokens: int | None = None
    max_evaluations: int | None = None
    seed: int = 0
    executor: str = "local"
    ray_address: str | None = None
    ray_cpus_per_task: float = 1.0
    ray_memory_mb: int | None = None

    def __post_init__(self) -> None:
        for name in ("iterations", "top_k", "workers"):
            if getattr(self, name) < 1:
                raise ConfigError(f"{name} must be at least 1, got {getattr(self, name)}")
        for name in ("exploit", "explore"):
            if getattr(self, name) < 0:
                raise ConfigError(f"{name} must be >= 0, got {getattr(self, name)}")
        if self.exploit + self.explore < 1:
            raise ConfigError("exploit + explore must be at least 1 (offspring per iteration)")
        for name in ("exploit_temperature", "explore_temperature"):
            if not 0 <= getattr(self, name) <= 2:
                raise ConfigError(f"{name} must lie in [0, 2], got {getattr(self, name)}")
        for name in ("max_usd", "max_tokens", "max_evaluations"):
            value = getattr(self, name)
            if value is not None and value <= 0:
                raise ConfigError(f"{name} must be positive, got {value}")
        self._check_executor()

    def _check_executor(self) -> None:
        if self.executor not in EXECUTORS:
            raise ConfigError(
                f"executor must be one of {', '.join(EXECUTORS)}, got {self.executor!r}"
            )
        defaults = {"ray_address": None, "ray_cpus_per_task": 1.0, "ray_memory_mb": None}
        given = [name for name, default in defaults.items() if getattr(self, name) != default]
        if self.executor != "ray" and given:
            raise ConfigError(f"{', '.join(given)} only apply to executor 'ray' (--executor ray)")
        address = self.ray_address
        if address is not None and address != "auto" and not _RAY_ADDRESS.match(address):
            raise ConfigError(
                f"ray_address must be HOST:PORT of the Ray head node (e.g. 10.0.0.5:6379) "
                f"or auto, got {address!r}"
            )
        cpus = self.ray_cpus_per_task
        if isinstance(cpus, bool) or not isinstance(cpus, (int, float)):
            raise ConfigError(f"ray_cpus_per_task must be a number, got {cpus!r}")
        if not (math.isfinite(cpus) and cpus > 0):
            raise ConfigError(f"ray_cpus_per_task must be positive, got {cpus}")
        memory = self.ray_memory_mb
        if memory is not None and (
            isinstance(memory, bool) or not isinstance(memory, int) or memory < 1
        ):
            raise ConfigError(f"ray_memory_mb must be a positive integer (MiB), got {memory!r}")

    @classmethod
    def from_preset(cls, preset: str, **settings: Any) -> SearchConfig:
        """The preset's values, overridden by ``settings`` that are not None."""
        if preset not in PRESETS:
            close = difflib.get_close_matches(preset, PRESETS, n=1)
            hint = f" Did you mean {close[0]!r}?" if close else ""
            raise ConfigError(
                f"unknown preset {preset!r}; choose one of {', '.join(PRESETS)}.{hint}"
            )
        values = {**PRESETS[preset], "preset": preset}
        values.update({key: value for key, value in settings.items() if value is not None})
        return cls(**values)

    @property
    def offspring(self) -> int:
        return self.exploit + self.explore

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SearchConfig:
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = set(data) - known
        if unknown:
            raise ConfigError(f"unknown settings in the run config: {', '.join(sorted(unknown))}")
        return cls(**data)
