"""Per-candidate overhead of the sandbox: process start, imports, isolation, Taichi's cache.

Printed side by side, as medians over ``--repeats`` runs:

- a trivial evaluation (a task that imports nothing heavy) called in this process, in a
  sandbox worker without isolation, and in an isolated one; split into the worker's start-up
  (interpreter, ``sga_agent`` imports, limits, isolation, loading the task: until the task's
  ``evaluate`` is entered) and the rest (writing and reading the result, cleaning up);
- inside a worker, with and without isolation: importing the constitutive task's modules
  (torch, Taichi, the bridges), ``taichi_mpm.init``, and the first and second run of a small
  forward simulation (the first loads its kernels from Taichi's offline cache).

Run ``taichi-mpm warmup`` first so that the cache holds the kernels. Usage::

    python benchmarks/sandbox_overhead.py [--repeats 10]
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from pathlib import Path

from sga_agent.isolation import detect_isolation
from sga_agent.sandbox import SandboxLimits, evaluate_in_sandbox
from sga_agent.task import Evaluation, EvaluationSettings, PromptParts

HERE = Path(__file__).resolve().parent
TASK = "sandbox_overhead:TimingTask"


class TimingTask:
    """Reports when ``evaluate`` was entered and, for "taichi", the Taichi timings."""

    name = "timing"
    description = "Measures the sandbox's overhead (a benchmark task)."
    kind = "equation"

    def seed_solution(self) -> str:
        return "trivial"

    def prompt_parts(self) -> PromptParts:
        return PromptParts(role="", context="", template="", requirements="")

    def evaluate(self, solution: str, settings: EvaluationSettings) -> Evaluation:
        entered = time.time()
        timings = taichi_timings() if solution == "taichi" else {}
        return Evaluation(True, 0.0, "", extras={"entered": entered, **timings})


def taichi_timings() -> dict[str, float]:
    """Seconds to import the constitutive modules, init Taichi, run a scene twice."""
    import numpy as np

    started = time.perf_counter()
    import taichi_mpm as tm
    import tasks.constitutive.evaluation  # noqa: F401 (torch, Taichi, bridges: the real imports)

    imported = time.perf_counter()
    tm.init(arch="cpu", precision="float32")
    initialised = time.perf_counter()
    positions, volume = tm.cube((0.5, 0.5, 0.5), 0.2, 2)
    scene = tm.Scene(positions, np.zeros_like(positions), volume, grid_resolution=8, steps=2)
    material = tm.Material(tm.FixedCorotated(E=1e4, nu=0.3), tm.VonMises(yield_stress=1e3))
    tm.Simulator(scene, material).forward()
    first = time.perf_counter()
    tm.Simulator(scene, material).forward()
    second = time.perf_counter()
    return {
        "import": imported - started,
        "init": initialised - imported,
        "first run": first - initialised,
        "second run": second - first,
    }


def median_of(repeats: int, measure: Callable[[], dict[str, float]]) -> dict[str, float]:
    runs = [measure() for _ in range(repeats)]
    return {key: statistics.median(run[key] for run in runs) for key in runs[0]}


def in_process() -> dict[str, float]:
    started = time.perf_counter()
    TimingTask().evaluate("trivial", EvaluationSettings())
    return {"total": time.perf_counter() - started, "start-up": 0.0}


def in_sandbox(solution: str, isolation: bool) -> dict[str, float]:
    limits = SandboxLimits(timeout_s=600, isolation=isolation)
    started = time.time()
    evaluation = evaluate_in_sandbox(
        TASK, solution, EvaluationSettings(), limits, extra_python_path=[HERE]
    )
    if not evaluation.valid:
        raise RuntimeError(f"the benchmark task failed: {evaluation.reason}")
    timings = {key: value for key, value in evaluation.extras.items() if key != "entered"}
    start_up = evaluation.extras["entered"] - started
    return {"total": evaluation.seconds, "start-up": start_up, **timings}


def show(title: str, columns: dict[str, dict[str, float]]) -> None:
    rows = list(next(iter(columns.values())))
    print(f"\n{title}")
    print(f"  {'seconds':<12}" + "".join(f"{name:>22}" for name in columns))
    for row in rows:
        print(f"  {row:<12}" + "".join(f"{column[row]:>22.4f}" for column in columns.values()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=10)
    args = parser.parse_args()
    isolation = detect_isolation()
    print("isolation:", *(f"  {key}: {value}" for key, value in vars(isolation).items()), sep="\n")
    in_sandbox("trivial", True)  # page the interpreter and packages into memory
    show(
        f"trivial evaluation (median of {args.repeats})",
        {
            "in process": median_of(args.repeats, in_process),
            "sandbox, no isolation": median_of(args.repeats, lambda: in_sandbox("trivial", False)),
            "sandbox, isolated": median_of(args.repeats, lambda: in_sandbox("trivial", True)),
        },
    )
    repeats = max(1, args.repeats // 3)
    show(
        f"constitutive imports and Taichi in a worker (median of {repeats})",
        {
            "sandbox, no isolation": median_of(repeats, lambda: in_sandbox("taichi", False)),
            "sandbox, isolated": median_of(repeats, lambda: in_sandbox("taichi", True)),
        },
    )


if __name__ == "__main__":
    main()
