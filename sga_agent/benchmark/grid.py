"""The cells of a benchmark grid (task x method x seed), each one search run, resumable.

Layout of the output folder::

    <task>/<method>/seed-<n>/<task>-<time>/   the cell's run folder, as `sga-agent search` writes

A cell whose run wrote its summary and end event is finished and skipped; one whose run folder
has no complete summary (stopped, killed) is resumed as ``sga-agent resume`` does (recorded
answers and evaluations are reused); a cell without a run folder starts. Cells run in worker
processes, ``parallel`` at a time, each with its own sandbox workers.
"""

from __future__ import annotations

import json
import multiprocessing
import re
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sga_agent import registry, runner
from sga_agent.config import ConfigError, SearchConfig
from sga_agent.events import IterationDone, RunResumed
from sga_agent.options import OptionError, option_names
from sga_agent.run_store import CONFIG, EVENTS, SUMMARY, RunStore, RunStoreError
from sga_agent.task import TaskBase, configured

#: Settings of where a cell runs, not what it computes: a recorded cell may differ in them.
NEUTRAL_SETTINGS = frozenset(
    {"workers", "api_base", "executor", "ray_address", "ray_cpus_per_task", "ray_memory_mb"}
)


class GridError(ValueError):
    """The grid cannot be planned, or a cell's folder conflicts with it; the message says why
    and what to do."""


def slug(label: str) -> str:
    """``label`` as a folder name: runs of characters other than letters, digits and ``._+-``
    become one ``-``."""
    return re.sub(r"[^A-Za-z0-9._+-]+", "-", label).strip("-") or "method"


@dataclass(frozen=True)
class Method:
    """One column of the table: who proposes, with which preset and settings.

    Parameters
    ----------
    label : str
        The column's name; made file-safe (:func:`slug`) it is the cell folders' name.
    proposer : str
        A litellm model string ("openai/gpt-4o"), "builtin" (or the task's built-in name,
        e.g. "builtin:gp"), or "replay:PATH": PATH is a run folder, or a folder holding run
        folders (such as the output of an earlier grid of one method), of which each cell
        replays the run of its task and seed.
    preset : str
        A :data:`~sga_agent.config.PRESETS` name.
    overrides : mapping
        :class:`~sga_agent.config.SearchConfig` settings (flat names) of this method only;
        they win over the grid's shared settings.
    """

    label: str
    proposer: str
    preset: str = "sga"
    overrides: Mapping[str, Any] = field(default_factory=dict)

    @property
    def folder(self) -> str:
        return slug(self.label)


@dataclass(frozen=True)
class Cell:
    """One search run of the grid: its task, method, seed, folder and resolved settings."""

    task: str
    method: Method
    seed: int
    folder: Path
    config: SearchConfig

    @property
    def name(self) -> str:
        return f"{self.task}/{self.method.folder}/seed-{self.seed}"


# ---------------------------------------------------------------------- planning


def plan_cells(
    tasks: Sequence[str],
    methods: Sequence[Method],
    seeds: Sequence[int],
    out: Path,
    settings: Mapping[str, Any] | None = None,
    options: Mapping[str, str] | None = None,
) -> list[Cell]:
    """Every cell of the grid, checked before anything runs.

    ``settings`` are :class:`~sga_agent.config.SearchConfig` values (flat names) shared by all
    cells (epochs, workers, ...), ``options`` the task options (``KEY=VALUE`` texts) of every
    cell, read by each task into its options once. Checked: names are registered tasks and
    presets, settings and options are valid, each proposer is available for each task (a
    built-in one exists, a model string is well-formed, a replayed run is found), and no cell
    folder holds a run with other settings.

    Raises
    ------
    GridError
        What is wrong, and the fix.
    """
    _check_axes(tasks, methods, seeds)
    loaded_tasks = {task: _load(task) for task in tasks}
    declared = {name: set(option_names(task.options_type)) for name, task in loaded_tasks.items()}
    cells = []
    for task, loaded in loaded_tasks.items():
        own = _options_of(task, options or {}, declared)
        for method in methods:
            try:
                typed = runner.task_options(loaded, own, method.proposer)
            except OptionError as error:
                raise GridError(f"--option: {error}") from error
            if not method.proposer.startswith(runner.REPLAY_PREFIX):
                try:
                    probe = SearchConfig(task=task, proposer=method.proposer, task_options=typed)
                    runner.make_proposer(probe, configured(loaded, typed))
                except ValueError as error:  # no such built-in, malformed model string
                    raise GridError(f"method {method.label!r} on task {task!r}: {error}") from error
            for seed in seeds:
                proposer = method.proposer
                if proposer.startswith(runner.REPLAY_PREFIX):
                    source = Path(proposer[len(runner.REPLAY_PREFIX) :])
                    proposer = f"{runner.REPLAY_PREFIX}{replay_source(source, task, seed)}"
                values = {**(settings or {}), **method.overrides}
                values.update(task=task, proposer=proposer, seed=seed, task_options=typed)
                try:
                    config = SearchConfig.from_preset(method.preset, **values)
                except ConfigError as error:
                    raise GridError(f"method {method.label!r}: {error}") from error
                folder = Path(out) / task / method.folder / f"seed-{seed}"
                cells.append(Cell(task, method, seed, folder, config))
    for cell in cells:
        cell_run(cell)  # a folder holding a run with other settings stops the grid here
    return cells


def _options_of(
    task: str, options: Mapping[str, str], declared: Mapping[str, set[str]]
) -> dict[str, str]:
    """The shared ``options`` that ``task`` declares (``declared``: each task's option names):
    an option goes to the tasks of the grid that have it (``steps`` to the constitutive tasks of
    a grid with a molecule task). An option no task of the grid has is given to every task,
    whose check then names it as unknown."""
    unknown = {key for key in options if not any(key in names for names in declared.values())}
    return {key: value for key, value in options.items() if key in declared[task] | unknown}


def _load(task: str) -> TaskBase:
    try:
        return registry.load_task(task)
    except Exception as error:  # a plugin may fail to import in any way
        raise GridError(
            f"task {task!r} could not be loaded: {type(error).__name__}: {error}"
        ) from error


def _check_axes(tasks: Sequence[str], methods: Sequence[Method], seeds: Sequence[int]) -> None:
    for axis, values in (("tasks", tasks), ("methods", methods), ("seeds", seeds)):
        if not values:
            raise GridError(f"the grid needs at least one of {axis}")
    for axis, names in (("task", list(tasks)), ("seed", list(seeds))):
        repeated = sorted({str(name) for name in names if names.count(name) > 1})
        if repeated:
            raise GridError(f"{axis} {', '.join(repeated)} given twice; list each once")
    folders: dict[str, str] = {}
    for method in methods:
        if method.folder in folders:
            raise GridError(
                f"methods {folders[method.folder]!r} and {method.label!r} would share the "
                f"folder {method.folder!r}; give them distinct labels (LABEL=PROPOSER)"
            )
        folders[method.folder] = method.label
    for task in tasks:
        try:
            registry.entry_point(task)
        except registry.UnknownTaskError as error:
            raise GridError(str(error)) from error


def replay_source(path: Path, task: str, seed: int) -> Path:
    """The recorded run a cell of ``task`` and ``seed`` replays from ``path``.

    ``path`` is a run folder (of ``task``) or a folder searched for run folders: the run of
    ``task`` with this seed, else the only run of ``task`` there.
    """
    if not path.is_dir():
        raise GridError(f"replay:{path}: no such folder; give a run folder or a folder of runs")
    runs: dict[Path, dict[str, Any]] = {}
    for config_file in sorted(path.rglob(CONFIG)):
        if (config_file.parent / EVENTS).is_file():
            runs[config_file.parent.resolve()] = _recorded(config_file.parent)
    if not runs:
        raise GridError(f"replay:{path} holds no run folder (a folder with {CONFIG} and {EVENTS})")
    of_task = {run: config for run, config in runs.items() if config.get("task") == task}
    if not of_task:
        found = ", ".join(sorted({str(config.get("task")) for config in runs.values()}))
        raise GridError(
            f"replay:{path} holds no run of task {task!r} (only of: {found}); replay it on "
            "those tasks, or point replay: at a folder with a run of each task"
        )
    same_seed = [run for run, config in of_task.items() if config.get("seed", 0) == seed]
    chosen = same_seed or list(of_task)
    if len(chosen) > 1:
        listing = ", ".join(str(run) for run in chosen[:4])
        raise GridError(
            f"replay:{path} holds {len(chosen)} runs of task {task!r} for seed {seed} "
            f"({listing}); point replay: at a folder with one run per task and seed"
        )
    return chosen[0]


def _recorded(run_dir: Path) -> dict[str, Any]:
    """The run's config as recorded (:meth:`~sga_agent.run_store.RunStore.config_record`)."""
    try:
        return RunStore.open(run_dir).config_record()
    except (RunStoreError, ValueError, KeyError) as error:
        raise GridError(f"{run_dir} is not a readable run folder: {error}") from error


def _recorded_config(run_dir: Path, options_type: type) -> SearchConfig:
    """The run's config, its task options an ``options_type`` object."""
    try:
        return RunStore.open(run_dir).config(options_type)
    except (RunStoreError, ConfigError, ValueError, KeyError) as error:
        raise GridError(f"{run_dir} is not a readable run folder: {error}") from error


# ---------------------------------------------------------------------- state of a cell


def cell_run(cell: Cell) -> RunStore | None:
    """The run recorded in the cell's folder, None if there is none.

    Raises
    ------
    GridError
        The folder holds several runs, or a run with other settings than the cell's.
    """
    runs = []
    if cell.folder.is_dir():
        runs = sorted(p for p in cell.folder.iterdir() if (p / CONFIG).is_file())
    if not runs:
        return None
    if len(runs) > 1:
        names = ", ".join(run.name for run in runs)
        raise GridError(f"{cell.folder} holds {len(runs)} runs ({names}); delete all but one")
    try:
        store = RunStore.open(runs[0])
    except RunStoreError as error:
        raise GridError(f"{runs[0]}: {error}; delete it to run the cell again") from error
    recorded = _recorded_config(store.path, type(cell.config.task_options)).settings()
    wanted = cell.config.settings()
    different = [
        f"{key}: {recorded.get(key)!r} there, {value!r} here"
        for key, value in wanted.items()
        if key not in NEUTRAL_SETTINGS and recorded.get(key) != value
    ]
    if different:
        raise GridError(
            f"{store.path} was run with other settings ({'; '.join(different)}); use another "
            "--out-dir, or delete that folder to run the cell again"
        )
    return store


def summary_of(store: RunStore) -> dict[str, Any] | None:
    """The run's summary if the run finished (complete summary.json and end event), else None."""
    try:
        summary = json.loads((store.path / SUMMARY).read_text(encoding="utf-8"))
    except (FileNotFoundError, json.JSONDecodeError):
        return None
    if not isinstance(summary, dict) or "best" not in summary:
        return None
    return summary if store.recorded().finished else None


# ---------------------------------------------------------------------- running


def say(text: str) -> None:
    """One progress line on stderr (cells print from their own processes)."""
    print(text, file=sys.stderr, flush=True)


def run_cell(cell: Cell) -> dict[str, Any]:
    """Start or resume the cell's search (in a worker process); returns its summary."""
    started = time.perf_counter()
    store = cell_run(cell)
    if store is None:
        meta = {
            "proposer": cell.config.proposer,
            "benchmark": {"task": cell.task, "method": cell.method.label, "seed": cell.seed},
        }
        store = RunStore.create(cell.folder, cell.config, meta)
        say(f"{cell.name}: started ({store.path})")
    else:
        store.append(RunResumed())
        say(f"{cell.name}: resumed ({store.path})")
    runner.run(cell.config, store, on_event=_progress(cell))
    summary = summary_of(store) or {}
    best = summary.get("best") or {}
    loss = best.get("loss") if best.get("valid") else "none valid"
    say(f"{cell.name}: finished in {time.perf_counter() - started:.0f} s, best loss {loss}")
    return summary


def _progress(cell: Cell) -> Callable[[dict[str, Any]], None]:
    def report(event: dict[str, Any]) -> None:
        if event.get("type") == IterationDone.type:
            top = event.get("top") or [{}]
            say(
                f"{cell.name}: iteration {event['iteration']}/{cell.config.loop.iterations}, "
                f"best loss {top[0].get('loss')}"
            )

    return report


def run_cells(cells: Sequence[Cell], parallel: int) -> list[tuple[Cell, str]]:
    """Run every cell that has not finished, ``parallel`` at a time, each in its own process.

    Finished cells are skipped, unfinished ones resumed. Returns the cells that failed, each
    with its error; the others have finished.
    """
    if parallel < 1:
        raise GridError(f"parallel must be at least 1, got {parallel}")
    pending, resumed = [], 0
    for cell in cells:
        store = cell_run(cell)
        if store is None or summary_of(store) is None:
            pending.append(cell)
            resumed += store is not None
    at_once = f"; {min(parallel, len(pending))} at once" if pending else ""
    say(
        f"{len(cells)} cells: {len(cells) - len(pending)} finished (skipped), {resumed} to "
        f"resume, {len(pending) - resumed} to start{at_once}"
    )
    if not pending:
        return []
    failures = []
    context = multiprocessing.get_context("spawn")  # no state of this process leaks into cells
    with ProcessPoolExecutor(max_workers=min(parallel, len(pending)), mp_context=context) as pool:
        futures = {pool.submit(run_cell, cell): cell for cell in pending}
        for future in as_completed(futures):
            cell = futures[future]
            error = future.exception()
            if error is not None:
                failures.append((cell, f"{type(error).__name__}: {error}"))
                say(f"{cell.name}: FAILED: {type(error).__name__}: {error}")
    return failures
