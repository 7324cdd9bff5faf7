"""Throughput of the executors: candidates per minute on the local pool and on Ray, side by side.

Both evaluate the same candidates in the same sandbox (a confined capture, then a trusted fit),
``--workers`` at a time: the local pool (:class:`~sga_agent.sandbox.SandboxPool`) in threads of
this process, its capture servers and fit workers kept warm from one candidate to the next;
Ray (:class:`~sga_agent.ray_executor.RayPool`) on the slots of a local Ray instance of
``--workers`` CPUs that the benchmark starts, each slot an actor whose capture server and fit
worker are kept warm the same way. The candidates are, by default, a cheap task whose fit keeps
one CPU busy for ``--work`` seconds (the sandbox's start-up and the capture come on top), or
``--task NAME`` (e.g. ``--task elastic --option steps=50 --epochs 1``): its seed solution,
evaluated again and again. Each pool first evaluates ``--workers`` candidates untimed (both
start their helpers); the pools' start-up is reported separately. With
``--repeats``, each pool runs that many times, alternately first and second, and the medians
are shown. Usage::

    python benchmarks/executors.py [--candidates 40] [--workers 2] [--work 0.5] [--repeats 3]
    python benchmarks/executors.py --task elastic --option steps=50 --epochs 1 --candidates 8
    python benchmarks/executors.py --search elastic --ray-address 127.0.0.2:6379 --repeats 2

``--ray-address`` uses a running cluster instead of a local instance. ``--search TASK`` times
whole searches instead: it records one search of TASK with its built-in proposer (the quick
preset, untimed), then replays its answers, so that both evaluate the same candidates, on the
local pool and on Ray alternately, and checks that every candidate's outcome is the same.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import wait
from pathlib import Path
from typing import Any

from sga_agent import registry, runner
from sga_agent.cli.options import key_value_options
from sga_agent.config import PRESETS, SearchConfig
from sga_agent.ray_executor import RayPool
from sga_agent.run_store import RunStore
from sga_agent.sandbox import SandboxLimits, SandboxPool
from sga_agent.task import (
    Evaluation,
    EvaluationSettings,
    InvalidSolution,
    PromptParts,
    TaskBase,
    configured,
)

HERE = Path(__file__).resolve().parent
BUSY_TASK = "executors:BusyTask"


class BusyTask:
    """The solution is a number of seconds to keep one CPU busy (a benchmark task).

    The CPU is kept busy in ``evaluate``, the trusted fit, where a real task spends its time
    (a constitutive law's simulation and inner optimization); ``capture`` only reads the number.
    """

    name = "busy"
    description = "Keeps a CPU busy for as many seconds as the solution says."
    kind = "equation"

    def seed_solution(self) -> str:
        return "0.5"

    def prompt_parts(self) -> PromptParts:
        return PromptParts(role="", context="", template="", requirements="")

    def capture(self, solution: str) -> dict[str, Any]:
        try:
            return {"seconds": float(solution.split()[0])}
        except (IndexError, ValueError):
            raise InvalidSolution("the solution must start with a number of seconds") from None

    def evaluate(self, data: dict[str, Any], settings: EvaluationSettings) -> Evaluation:
        seconds = data.get("seconds") if isinstance(data, dict) else None
        if not isinstance(seconds, (int, float)) or not 0 <= seconds <= 3600:
            return Evaluation.invalid("the captured work is not a number of seconds in [0, 3600]")
        deadline = time.process_time() + seconds
        spins = 0
        while time.process_time() < deadline:
            spins += 1
        return Evaluation(True, 0.0, "", extras={"spins": spins})


def throughput(pool: SandboxPool | RayPool, task: str, solutions: list[str], settings) -> float:
    """Seconds to evaluate ``solutions`` (all submitted at once); every one must be valid."""
    started = time.perf_counter()
    futures = [pool.submit(task, solution, settings) for solution in solutions]
    wait(futures)
    seconds = time.perf_counter() - started
    failed = [future.result() for future in futures if not future.result().valid]
    if failed:
        raise RuntimeError(f"{len(failed)} evaluations failed, e.g.: {failed[0].reason}")
    return seconds


def measure(
    name: str, make: Callable[[], SandboxPool | RayPool], task: str, solutions: list[str],
    settings: EvaluationSettings, workers: int,
) -> dict[str, float]:  # fmt: skip
    """Start-up, warm-up (untimed in the throughput) and the timed evaluations of one pool."""
    started = time.perf_counter()
    with make() as pool:
        start_up = time.perf_counter() - started
        throughput(pool, task, [f"{solutions[0]}\n# warm-up {i}" for i in range(workers)], settings)
        seconds = throughput(pool, task, solutions, settings)
    print(f"  {name}: {len(solutions)} candidates in {seconds:.1f} s", flush=True)
    return {"start-up s": start_up, "seconds": seconds, "per minute": 60 * len(solutions) / seconds}


def search_seconds(
    config: SearchConfig, task: TaskBase, folder: Path
) -> tuple[float, dict[str, dict]]:
    """Wall time of one whole search of ``task`` (set up for the config's options; pool
    start-up included) and its candidates' outcomes."""
    started = time.perf_counter()
    store = RunStore.create(folder, config, {})
    runner.run(config, store, task=task)
    seconds = time.perf_counter() - started
    outcomes = {}
    for candidate in sorted((store.path / "candidates").iterdir()):
        evaluation = json.loads((candidate / "evaluation.json").read_text())
        outcomes[candidate.name] = (evaluation["status"], evaluation["loss"])
    return seconds, outcomes


def compare_searches(args: argparse.Namespace, raw: dict[str, str]) -> None:
    """Record a quick search of ``args.search``, then time its replays on both executors."""
    folder = Path(tempfile.mkdtemp(prefix="executors-search-"))
    loaded = registry.load_task(args.search)
    options = runner.task_options(loaded, raw, runner.BUILTIN)
    task = configured(loaded, options)
    preset = {k: v for k, v in PRESETS["quick"].items() if k != "bilevel"}
    base = SearchConfig.from_settings(
        task=args.search, proposer=runner.BUILTIN, preset="quick", workers=args.workers,
        task_options=options, **preset,
    )  # fmt: skip
    print(f"recording a quick search of {args.search} (untimed) ...", flush=True)
    _, recorded = search_seconds(base, task, folder / "recorded")
    (recorded_path,) = (folder / "recorded").iterdir()
    replay = base.replace(proposer=f"{runner.REPLAY_PREFIX}{recorded_path}")
    configs = {
        "local": replay,
        "ray": replay.replace(executor="ray", ray_address=args.ray_address),
    }
    seconds: dict[str, list[float]] = {name: [] for name in configs}
    load_before = os.getloadavg()
    for repeat in range(args.repeats):
        for name in sorted(configs, reverse=repeat % 2 == 1):
            took, outcomes = search_seconds(configs[name], task, folder / f"{name}-{repeat}")
            if outcomes != recorded:
                raise RuntimeError(f"the {name} replay's outcomes differ from the recorded run")
            seconds[name].append(took)
            print(f"  {name}: {len(outcomes)} candidates in {took:.1f} s", flush=True)
    load_after = os.getloadavg()
    local, ray = (statistics.median(seconds[name]) for name in ("local", "ray"))
    where = args.ray_address or f"a local Ray instance of {args.workers} CPUs"
    print(f"\n{len(recorded)} candidates of a quick {args.search} search, {args.workers} at a "
          f"time; Ray on {where}; load average before {load_before[0]:.2f}, "
          f"after {load_after[0]:.2f}")
    print(f"local {local:.1f} s, Ray {ray:.1f} s (medians of {args.repeats}): Ray / local "
          f"wall time {ray / local:.2f}; every outcome the same as the recorded run's")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--candidates", type=int, default=40, help="timed evaluations per pool")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--work", type=float, default=0.5, help="CPU seconds per cheap candidate")
    parser.add_argument("--task", help="a registered task: evaluate its seed solution instead")
    parser.add_argument("--option", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--epochs", type=int, help="inner-optimization epochs of --task")
    parser.add_argument("--timeout", type=float, default=900.0, help="limit per evaluation (s)")
    parser.add_argument("--repeats", type=int, default=1, help="runs per pool, interleaved")
    parser.add_argument("--ray-address", help="a running Ray cluster (HOST:PORT) to use")
    parser.add_argument("--search", metavar="TASK", help="time whole searches of TASK instead")
    args = parser.parse_args()

    raw = key_value_options(args.option)
    if args.search:
        compare_searches(args, raw)
        return
    options = None
    if args.task:
        loaded = registry.load_task(args.task)
        task, seed = args.task, loaded.seed_solution()
        options = runner.task_options(loaded, raw, "")
    else:
        task, seed = BUSY_TASK, str(args.work)
    settings = EvaluationSettings(epochs=args.epochs, options=options)
    solutions = [f"{seed}\n# candidate {i}" for i in range(args.candidates)]
    limits = SandboxLimits(timeout_s=args.timeout)
    paths = [] if args.task else [HERE]
    print(f"{args.candidates} candidates of {args.task or f'{args.work:g} CPU s'}, "
          f"{args.workers} at a time, on {os.cpu_count()} cores", flush=True)  # fmt: skip
    pools: dict[str, Callable[[], SandboxPool | RayPool]] = {
        "local": lambda: SandboxPool(args.workers, limits, extra_python_path=paths),
        "ray": lambda: RayPool(args.ray_address, limits, local_cpus=args.workers,
                               extra_python_path=paths),  # fmt: skip
    }
    runs: dict[str, list[dict[str, float]]] = {name: [] for name in pools}
    for repeat in range(args.repeats):  # alternating the order evens out a drifting load
        for name in sorted(pools, reverse=repeat % 2 == 1):
            measured = measure(name, pools[name], task, solutions, settings, args.workers)
            runs[name].append(measured)
    results = {
        name: {key: statistics.median(run[key] for run in measured) for key in measured[0]}
        for name, measured in runs.items()
    }
    print(f"\n| executor | start-up | {args.candidates} candidates | candidates / minute |")
    print("|---|---|---|---|")
    for name, row in results.items():
        print(f"| {name} | {row['start-up s']:.1f} s | {row['seconds']:.1f} s "
              f"| {row['per minute']:.1f} |")  # fmt: skip
    ratio = results["ray"]["per minute"] / results["local"]["per minute"]
    print(f"\nRay / local throughput: {ratio:.2f} (medians of {args.repeats} runs each)")


if __name__ == "__main__":
    main()
