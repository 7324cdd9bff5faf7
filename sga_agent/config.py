"""Settings of one search run, and the presets that reproduce the paper's Table 1 columns.

A run is described by a :class:`SearchConfig`: the task with its typed options, the proposer,
and one config per component, as OpenEvolve and ShinkaEvolve give each of theirs: the outer
loop (:class:`LoopConfig`), the inner fit (:class:`FitConfig`), the sandbox
(:class:`SandboxConfig`), the executor (:class:`ExecutorConfig`), how the model is asked
(:class:`ModelConfig`) and the budgets (:class:`Budgets`). It is written to the run folder
(:meth:`SearchConfig.to_dict`), so ``sga-agent resume`` continues with exactly the same
settings.

Each setting also has a flat name (:data:`SETTINGS`): the command line's, that of the
benchmarks' ``--set``, and its key in the ``config.json`` of runs written before the components
existed, which :func:`current_format` reads.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from sga_agent.options import OptionError, options_data, options_from_data
from sga_agent.sandbox import SandboxLimits
from sga_agent.task import EvaluationSettings, NoOptions

if TYPE_CHECKING:
    from sga_agent.search import Totals

#: Iterations, top-K shown, exploit/explore offspring per iteration, bilevel on or off. All but
#: "quick" are the columns of the paper's Table 1; "quick" is the default of the LLM-free
#: built-in proposers: a short run (4 iterations of 6 candidates, 5 inner epochs), preferring
#: the law with fewer constants where two are within 1 % a constant
#: (``benchmarks/discovery.py``, observed neo-Hookean: a three-constant law 0.07 % below the
#: true form held out worse). The command line also screens its candidates where the task
#: screens cheaply, after a wide opening with a built-in proposer (:func:`quick_screening`).
PRESETS: dict[str, dict[str, Any]] = {
    "quick": {
        "iterations": 4, "top_k": 5, "exploit": 2, "explore": 4, "bilevel": True, "epochs": 5,
        "parsimony": 0.01,
    },
    "sga": {"iterations": 5, "top_k": 5, "exploit": 4, "explore": 12, "bilevel": True},
    "no-bilevel": {"iterations": 5, "top_k": 5, "exploit": 4, "explore": 12, "bilevel": False},
    "no-exploit": {"iterations": 5, "top_k": 5, "exploit": 0, "explore": 16, "bilevel": True},
    "cot": {"iterations": 1, "top_k": 5, "exploit": 1, "explore": 0, "bilevel": False},
    "funsearch": {"iterations": 20, "top_k": 2, "exploit": 0, "explore": 4, "bilevel": False},
    "eureka": {"iterations": 5, "top_k": 1, "exploit": 0, "explore": 16, "bilevel": False},
    "opro": {"iterations": 5, "top_k": 5, "exploit": 0, "explore": 16, "bilevel": False},
}

#: Iterations of a preset's search given a wall-time budget and no iteration count: as many
#: as the budget allows (a bound no search reaches).
UNTIL_BUDGET = 1_000_000


#: A tenth of each iteration's screens is fitted in full in the quick preset's search with an
#: opening (4 of the opening's 40; ``benchmarks/discovery.py --budget none`` measures it).
OPENING_PROMOTE = 0.1


def quick_screening(
    preset: str,
    settings: dict[str, Any],
    screens_cheaply: bool,
    opening: tuple[int, float] | None = None,
) -> dict[str, Any]:
    """The settings the ``quick`` preset adds to ``settings`` where they leave them unset, on
    a task that screens cheaply and without a time budget.

    With the task's built-in proposer (``opening``: the answers and the screen fidelity of the
    task's opening, its ``opening_answers`` and ``opening_screen``) and the preset's
    iterations, exploit and explore counts: a wide first iteration of that many answers (the
    proposer's most likely forms), screens at that fidelity, a tenth of each iteration's
    screens promoted below the K-th best earlier screen.
    Otherwise (a model, or a search shaped by the command): its candidates screened at 0.2 of
    a fit and promoted below the K-th best earlier screen (a short search needs its few full
    fits: with multi's own defaults, 0.1 and the bar at the best, the main command of the
    release before ended at 1.60e-5 against 3.99e-6 in the same time). A budgeted search
    fits every candidate in full unless told otherwise (the discovery benchmark's rows were
    measured so); ``--fidelity multi`` there takes multi's defaults, which buy several times
    the candidates in equal time (``benchmarks/fidelity.py``; its figures are on the
    benchmarks page)."""
    fidelity = settings.get("fidelity")
    if preset != "quick" or settings.get("max_seconds") is not None or fidelity == "full":
        return {}
    if fidelity is None and not screens_cheaply:
        return {}
    rank = settings.get("top_k") or PRESETS[preset]["top_k"]
    screening: dict[str, Any] = {"fidelity": "multi", "screen_fidelity": 0.2, "promote_rank": rank}
    shaped = any(settings.get(name) is not None for name in ("iterations", "exploit", "explore"))
    if opening is not None and screens_cheaply and not shaped:
        answers, fidelity = opening
        screening |= {"opening": answers, "screen_fidelity": fidelity,
                      "promote": OPENING_PROMOTE}  # fmt: skip
    return {name: value for name, value in screening.items() if settings.get(name) is None}


#: Full fits only, or screens and full fits of the promoted (:class:`LoopConfig`).
FIDELITIES = ("full", "multi")
#: Where candidates are evaluated: this machine's process pool, or a Ray cluster.
EXECUTORS = ("local", "ray")
#: A Ray head node's GCS address, HOST:PORT (the port ``ray start --head`` printed).
_RAY_ADDRESS = re.compile(r"^[A-Za-z0-9._-]+:\d{1,5}$")
#: The version of :meth:`SearchConfig.to_dict`'s layout (runs without one are flat).
FORMAT = 2


class ConfigError(ValueError):
    """A search setting is invalid; the message names it and the fix."""


def _at_least(config: Any, names: tuple[str, ...], minimum: int, wording: str) -> None:
    for name in names:
        value = getattr(config, name)
        if value < minimum:
            raise ConfigError(f"{name} must be {wording}, got {value}")


@dataclass(frozen=True)
class LoopConfig:
    """The outer loop (Algorithm 1 of the paper).

    Parameters
    ----------
    iterations : int
        Outer iterations.
    top_k : int
        Solutions shown per prompt (K).
    exploit : int
        Offspring per iteration asked at the exploit (low) temperature (M_l).
    explore : int
        Offspring per iteration asked at the explore (high) temperature (M_h).
    exploit_temperature : float
        T_l (paper: 0.5).
    explore_temperature : float
        T_h (paper: 1.0).
    fidelity : str
        "full": every candidate gets the full fit. "multi": every candidate is first screened
        by a cheaper fit (``screen_fidelity``, see
        :attr:`~sga_agent.task.EvaluationSettings.fidelity`) and the best ``promote`` share of
        an iteration's valid screens (rounded up, at least one) that beat the
        ``promote_rank``-th best valid screen of the earlier iterations gets the full fit; only
        full fits enter the heap, the prompt and the parents.
    screen_fidelity : float
        The screen's share of the full fit's work, in (0, 1).
    promote : float
        The share of an iteration's valid screens promoted to the full fit, in (0, 1].
    promote_rank : int, optional
        The rank of the earlier screen a screen must beat to be promoted (1: only a possible
        new best; None, as runs recorded before this default read: ``top_k``, i.e. its screen
        says it may enter the top K).
    parsimony : float
        The share of the loss a fitted parameter must win to rank a solution higher: solutions
        rank by loss * (1 + parsimony) ** (fitted parameters), so of two laws a tenth of a
        percent apart (within the noise of an observation) the one with fewer constants leads.
        0 ranks by loss alone (the paper), in [0, 1).
    opening : int
        Explore answers of the first iteration when more than ``explore``: a wide first look
        (the constitutive tasks' built-in proposer answers it with its list of likely forms,
        :mod:`tasks.constitutive.gp.enumeration`); 0: the first iteration is like the others.
    """

    iterations: int = 5
    top_k: int = 5
    exploit: int = 4
    explore: int = 12
    exploit_temperature: float = 0.5
    explore_temperature: float = 1.0
    fidelity: str = "full"
    screen_fidelity: float = 0.1
    promote: float = 0.25
    promote_rank: int | None = 1
    parsimony: float = 0.0
    opening: int = 0

    def __post_init__(self) -> None:
        _at_least(self, ("iterations", "top_k"), 1, "at least 1")
        _at_least(self, ("exploit", "explore", "opening"), 0, ">= 0")
        if self.offspring < 1:
            raise ConfigError("exploit + explore must be at least 1 (offspring per iteration)")
        for name in ("exploit_temperature", "explore_temperature"):
            if not 0 <= getattr(self, name) <= 2:
                raise ConfigError(f"{name} must lie in [0, 2], got {getattr(self, name)}")
        if self.fidelity not in FIDELITIES:
            raise ConfigError(
                f"fidelity must be one of {', '.join(FIDELITIES)}, got {self.fidelity!r}"
            )
        if not 0 < self.screen_fidelity < 1:
            raise ConfigError(f"screen_fidelity must lie in (0, 1), got {self.screen_fidelity}")
        if not 0 < self.promote <= 1:
            raise ConfigError(f"promote must lie in (0, 1], got {self.promote}")
        if not 0 <= self.parsimony < 1:
            raise ConfigError(f"parsimony must lie in [0, 1), got {self.parsimony}")
        if self.promote_rank is not None and self.promote_rank < 1:
            raise ConfigError(f"promote_rank must be at least 1, got {self.promote_rank}")

    @property
    def offspring(self) -> int:
        """Candidates proposed per iteration (the first one may explore more: ``opening``)."""
        return self.exploit + self.explore

    def explore_in(self, iteration: int) -> int:
        """Explore answers asked in ``iteration``: ``opening`` in the first where it is more."""
        return max(self.explore, self.opening) if iteration == 1 else self.explore

    def offspring_in(self, iteration: int) -> int:
        """Candidates proposed in ``iteration``."""
        return self.exploit + self.explore_in(iteration)

    @property
    def candidates(self) -> int:
        """Candidates of a search that runs every iteration, the seed included."""
        return 1 + self.iterations * self.offspring + self.explore_in(1) - self.explore


@dataclass(frozen=True)
class FitConfig:
    """The inner loop: how each candidate's continuous parameters are fitted.

    Parameters
    ----------
    bilevel : bool
        Fit them (off: evaluate the defaults as proposed).
    epochs : int, optional
        Epochs of the inner optimization (default: the task's).
    learning_rate : float, optional
        Learning rate of the inner optimization (default: the task's).
    """

    bilevel: bool = True
    epochs: int | None = None
    learning_rate: float | None = None

    def __post_init__(self) -> None:
        if self.epochs is not None and self.epochs < 0:
            raise ConfigError(f"epochs must be >= 0, got {self.epochs}")
        if self.learning_rate is not None and not self.learning_rate > 0:
            raise ConfigError(f"learning_rate must be positive, got {self.learning_rate}")


@dataclass(frozen=True)
class SandboxConfig:
    """Limits of one evaluation: wall clock ``timeout_s`` (seconds) and ``memory_mb`` (MiB),
    as :class:`~sga_agent.sandbox.SandboxLimits` applies them, and the ``device`` its fit
    computes on (``cpu`` or ``cuda``, :mod:`sga_agent.task.device`)."""

    timeout_s: float = SandboxLimits.timeout_s
    memory_mb: int = SandboxLimits.memory_mb
    device: str = SandboxLimits.device

    def __post_init__(self) -> None:
        try:
            self.limits(threads=1)
        except (TypeError, ValueError) as error:
            raise ConfigError(str(error)) from None

    def limits(self, threads: int) -> SandboxLimits:
        """The sandbox's limits, with ``threads`` for each fit's parallel loops."""
        return SandboxLimits(timeout_s=self.timeout_s, memory_mb=self.memory_mb, threads=threads,
                             device=self.device)  # fmt: skip


@dataclass(frozen=True)
class ExecutorConfig:
    """Where candidates are evaluated.

    Parameters
    ----------
    kind : str
        "local" (a pool of sandboxed processes on this machine) or "ray" (each evaluation a
        Ray task running the same sandboxed worker on a node of a Ray cluster); the setting
        ``executor``.
    workers : int
        Candidates evaluated at once, each in its own sandboxed process (with Ray: the size of
        the local Ray instance started when no address is given).
    ray_address : str, optional
        The Ray cluster: "HOST:PORT" of its head node, or "auto" (``RAY_ADDRESS``, else a
        cluster started on this machine with ``ray start``); None starts a private local Ray
        instance for the run.
    ray_cpus_per_task : float
        CPUs each evaluation reserves in Ray.
    ray_memory_mb : int, optional
        Memory in MiB each evaluation reserves in Ray (None: none).
    """

    kind: str = "local"
    workers: int = field(default_factory=lambda: os.cpu_count() or 1)
    ray_address: str | None = None
    ray_cpus_per_task: float = 1.0
    ray_memory_mb: int | None = None

    def __post_init__(self) -> None:
        _at_least(self, ("workers",), 1, "at least 1")
        if self.kind not in EXECUTORS:
            raise ConfigError(f"executor must be one of {', '.join(EXECUTORS)}, got {self.kind!r}")
        defaults = {"ray_address": None, "ray_cpus_per_task": 1.0, "ray_memory_mb": None}
        given = [name for name, default in defaults.items() if getattr(self, name) != default]
        if self.kind != "ray" and given:
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


@dataclass(frozen=True)
class ModelConfig:
    """How the model is asked (a litellm proposer's settings; the others ignore them).

    Parameters
    ----------
    request_timeout_s : float
        Seconds one request may take before it counts as failed and is retried.
    retries : int
        Further attempts after a timeout, rate limit, server error or empty answer; when they
        run out the search stops, resumable.
    prompt_tokens : int, optional
        The most tokens a prompt may hold (litellm's counter for the model): the earlier
        solutions' feedback is shortened, the worst first, until it fits. The default keeps a
        prompt at K = 5 within an 8k-context model with room for the answer; None: no bound.
    price : (float, float), optional
        USD per million input and output tokens, for a model litellm cannot price (needed
        for ``max_usd`` then); None: litellm's price map.
    """

    request_timeout_s: float = 120.0
    retries: int = 4
    prompt_tokens: int | None = 6000
    price: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.request_timeout_s) and self.request_timeout_s > 0):
            raise ConfigError(f"request_timeout_s must be positive, got {self.request_timeout_s}")
        _at_least(self, ("retries",), 0, ">= 0")
        if self.prompt_tokens is not None and self.prompt_tokens < 500:
            raise ConfigError(
                f"prompt_tokens must be at least 500 (the task and format alone need about "
                f"that), got {self.prompt_tokens}"
            )
        price = self.price
        if price is not None:
            if isinstance(price, str) or len(price) != 2:
                raise ConfigError(
                    f"price must be two numbers, USD per million input and output tokens "
                    f"(e.g. 2.5,10), got {price!r}"
                )
            values = tuple(float(p) for p in price)
            if not all(math.isfinite(p) and p >= 0 for p in values):
                raise ConfigError(f"price must be two numbers >= 0, got {price!r}")
            object.__setattr__(self, "price", values)


#: The share of a time budget a run's end is given (the best law's assessment, after the
#: evaluations), and its most seconds.
END_SHARE = 0.03
END_SECONDS = 30.0


@dataclass(frozen=True)
class Budgets:
    """Limits at which a run stops cleanly (None: none): ``max_usd`` spent on the model,
    ``max_tokens`` it used, ``max_evaluations`` run, ``max_seconds`` of wall time (over all
    the run's sessions, a resume included). A budget is a field here and a line in
    :meth:`spent_of`; the loop checks them all through :meth:`exceeded`, before each
    iteration, each request to the proposer and each evaluation it submits. Evaluations
    already submitted finish, except at ``max_seconds``: those still running then are
    stopped, where the evaluator can stop them, and left for a resume. The evaluations of a
    time budget end :meth:`kept_for_end` seconds before it, the time a run's end (the best
    law's assessment) is given."""

    max_usd: float | None = None
    max_tokens: int | None = None
    max_evaluations: int | None = None
    max_seconds: float | None = None

    def __post_init__(self) -> None:
        for name, limit in vars(self).items():
            if limit is not None and limit <= 0:
                raise ConfigError(f"{name} must be positive, got {limit}")

    @staticmethod
    def spent_of(totals: Totals) -> dict[str, float]:
        """What each budget measures, in ``totals``."""
        return {
            "max_usd": totals.cost_usd,
            "max_tokens": totals.tokens,
            "max_evaluations": totals.evaluations,
            "max_seconds": totals.seconds,
        }

    def kept_for_end(self) -> float:
        """Seconds of the time budget kept for a run's end, after its evaluations: a share
        (:data:`END_SHARE`) of ``max_seconds``, at most :data:`END_SECONDS`; 0 without one."""
        if self.max_seconds is None:
            return 0.0
        return min(END_SHARE * self.max_seconds, END_SECONDS)

    def exceeded(
        self, totals: Totals, names: tuple[str, ...] | None = None, kept: float = 0.0
    ) -> str:
        """The first budget (of ``names``; default all) ``totals`` has reached, as
        "max_usd=5.0 reached"; "" if none. ``kept`` seconds of the time budget count as
        spent (see :meth:`kept_for_end`)."""
        for name, spent in self.spent_of(totals).items():
            if names is not None and name not in names:
                continue
            limit = getattr(self, name)
            if name == "max_seconds":
                spent += kept
            if limit is not None and spent >= limit:
                return self.reached(name)
        return ""

    def reached(self, name: str) -> str:
        """How a run stopped by budget ``name`` says so: "max_usd=5.0 reached"."""
        return f"{name}={getattr(self, name)} reached"


#: The components of a run's config, by their field in :class:`SearchConfig`.
COMPONENTS: dict[str, type] = {
    "loop": LoopConfig, "fit": FitConfig, "sandbox": SandboxConfig, "executor": ExecutorConfig,
    "model": ModelConfig, "budgets": Budgets,
}  # fmt: skip
#: Every component setting by its flat name: its component and its field there.
SETTINGS: dict[str, tuple[str, str]] = {
    ("executor" if (part, f.name) == ("executor", "kind") else f.name): (part, f.name)
    for part, kind in COMPONENTS.items()
    for f in dataclasses.fields(kind)
}
#: The settings of the run itself (not of a component).
RUN_SETTINGS = ("task", "proposer", "task_options", "api_base", "preset", "seed")


def setting_field(name: str) -> dataclasses.Field:
    """The dataclass field that holds the setting ``name`` (a flat name, or a run setting)."""
    if name in SETTINGS:
        part, attribute = SETTINGS[name]
        return next(f for f in dataclasses.fields(COMPONENTS[part]) if f.name == attribute)
    return next(f for f in dataclasses.fields(SearchConfig) if f.name == name)


def default(name: str) -> Any:
    """The default of the setting ``name`` (the command line's defaults are the config's)."""
    found = setting_field(name)
    if found.default_factory is not dataclasses.MISSING:
        return found.default_factory()
    return found.default


@dataclass(frozen=True)
class SearchConfig:
    """Everything that determines a search run.

    Parameters
    ----------
    task : str
        Registered task name (``sga-agent tasks``).
    proposer : str
        Who proposes: a litellm model string ("openai/gpt-4o"), "builtin", or
        "replay:RUN_DIR".
    task_options : object
        The task's options: an object of its ``options_type``
        (:func:`sga_agent.options.parse_options` reads one from ``KEY=VALUE`` text); the
        default, :class:`~sga_agent.task.NoOptions`, fits only a task that declares none.
    api_base : str, optional
        Base URL of an OpenAI-compatible server (local models).
    preset : str
        The preset the settings started from (a record: its values are in the components).
    seed : int
        Seed passed to the evaluations and the offline proposers.
    loop : LoopConfig
        The outer loop.
    fit : FitConfig
        The inner fit.
    sandbox : SandboxConfig
        The evaluation processes' limits.
    executor : ExecutorConfig
        Where evaluations run.
    model : ModelConfig
        The language model's requests.
    budgets : Budgets
        When the search stops.
    """

    task: str
    proposer: str
    task_options: Any = field(default_factory=NoOptions)
    api_base: str | None = None
    preset: str = "sga"
    seed: int = 0
    loop: LoopConfig = field(default_factory=LoopConfig)
    fit: FitConfig = field(default_factory=FitConfig)
    sandbox: SandboxConfig = field(default_factory=SandboxConfig)
    executor: ExecutorConfig = field(default_factory=ExecutorConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    budgets: Budgets = field(default_factory=Budgets)

    def __post_init__(self) -> None:
        try:
            options_data(self.task_options)
        except TypeError as error:
            raise ConfigError(str(error)) from None
        for part, kind in COMPONENTS.items():
            if not isinstance(getattr(self, part), kind):
                raise ConfigError(f"{part} must be a {kind.__name__}, got {getattr(self, part)!r}")

    @classmethod
    def from_settings(cls, **settings: Any) -> SearchConfig:
        """The config of ``settings`` by their flat names (:data:`SETTINGS` and the run's own,
        :data:`RUN_SETTINGS`); the rest take their defaults."""
        run, parts = _by_component(settings)
        return cls(**run, **{part: COMPONENTS[part](**values) for part, values in parts.items()})

    @classmethod
    def from_preset(cls, preset: str, **settings: Any) -> SearchConfig:
        """The preset's values, overridden by ``settings`` (flat names) that are not None; with
        a wall-time budget (``max_seconds``) and no ``iterations``, the search iterates until
        the budget (:data:`UNTIL_BUDGET`)."""
        if preset not in PRESETS:
            close = difflib.get_close_matches(preset, PRESETS, n=1)
            hint = f" Did you mean {close[0]!r}?" if close else ""
            raise ConfigError(
                f"unknown preset {preset!r}; choose one of {', '.join(PRESETS)}.{hint}"
            )
        values = {**PRESETS[preset], "preset": preset}
        if settings.get("max_seconds") is not None and settings.get("iterations") is None:
            values["iterations"] = UNTIL_BUDGET
        values.update({key: value for key, value in settings.items() if value is not None})
        return cls.from_settings(**values)

    def replace(self, **settings: Any) -> SearchConfig:
        """This config with the settings given (by their flat names) changed."""
        run, parts = _by_component(settings)
        changed = {part: dataclasses.replace(getattr(self, part), **values)
                   for part, values in parts.items()}  # fmt: skip
        return dataclasses.replace(self, **run, **changed)

    def evaluation_settings(self) -> EvaluationSettings:
        """What each evaluation of the run is given."""
        return EvaluationSettings(
            epochs=self.fit.epochs if self.fit.bilevel else 0,
            learning_rate=self.fit.learning_rate,
            seed=self.seed,
            options=self.task_options,
        )

    def to_dict(self) -> dict[str, Any]:
        """The config as JSON data (the layout :data:`FORMAT`), the task options a dict."""
        data: dict[str, Any] = {"format": FORMAT}
        data.update({name: getattr(self, name) for name in RUN_SETTINGS})
        data["task_options"] = options_data(self.task_options)
        data.update({part: dataclasses.asdict(getattr(self, part)) for part in COMPONENTS})
        return data

    def settings(self) -> dict[str, Any]:
        """Every setting by its flat name, the task options a dict."""
        return flat_settings(self.to_dict())

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], options_type: type) -> SearchConfig:
        """The config :meth:`to_dict` wrote, or that a run written before the components
        recorded (flat); its task options built as an ``options_type`` object.

        Raises
        ------
        ConfigError
            A setting this version does not know, or a value it refuses.
        """
        record = current_format(data)
        known = {"format", *RUN_SETTINGS, *COMPONENTS}
        unknown = [f"{name}" for name in record if name not in known]
        for part, kind in COMPONENTS.items():
            names = {f.name for f in dataclasses.fields(kind)}
            unknown += [f"{part}.{name}" for name in record.get(part, {}) if name not in names]
        if unknown:
            raise ConfigError(f"unknown settings in the run config: {', '.join(sorted(unknown))}")
        try:
            options = options_from_data(options_type, record.get("task_options") or {},
                                        str(record.get("task")))  # fmt: skip
        except OptionError as error:
            raise ConfigError(f"the run's task options: {error}") from None
        run = {name: record[name] for name in RUN_SETTINGS if name in record}
        parts = {part: kind(**record.get(part, {})) for part, kind in COMPONENTS.items()}
        return cls(**{**run, "task_options": options}, **parts)


def _by_component(settings: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, dict]]:
    """``settings`` (flat names) split into the run's own and each component's."""
    run: dict[str, Any] = {}
    parts: dict[str, dict[str, Any]] = {}
    for name, value in settings.items():
        if name in RUN_SETTINGS:
            run[name] = value
        elif name in SETTINGS:
            part, attribute = SETTINGS[name]
            parts.setdefault(part, {})[attribute] = value
        else:
            names = [*RUN_SETTINGS, *SETTINGS]
            close = difflib.get_close_matches(name, names, n=1)
            hint = f" Did you mean {close[0]!r}?" if close else ""
            raise ConfigError(f"no search setting {name!r} (known: {', '.join(names)}).{hint}")
    return run, parts


def current_format(data: Mapping[str, Any]) -> dict[str, Any]:
    """A run's config record in the current layout: itself, or, for a run written before the
    components existed (flat: every setting by its flat name), its settings put into their
    components. Names it does not know stay where they are (:meth:`SearchConfig.from_dict`
    refuses them, a report shows them)."""
    if "format" in data:
        return dict(data)
    record: dict[str, Any] = {"format": FORMAT}
    for name, value in data.items():
        if name in SETTINGS:
            part, attribute = SETTINGS[name]
            record.setdefault(part, {})[attribute] = value
        else:
            record[name] = value
    return record


def flat_settings(record: Mapping[str, Any]) -> dict[str, Any]:
    """Every setting a config record (current layout) holds, by its flat name."""
    flat = {name: value for name, value in record.items()
            if name not in COMPONENTS and name != "format"}  # fmt: skip
    for name, (part, attribute) in SETTINGS.items():
        values = record.get(part)
        if isinstance(values, Mapping) and attribute in values:
            flat[name] = values[attribute]
    return flat
