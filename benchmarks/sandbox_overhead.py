"""Per-candidate cost of the sandbox: the confined capture, the fit worker, warm or fresh.

The sandbox evaluates a candidate in two steps (:mod:`sga_agent.sandbox`): a capture server
forks a confined process that runs the task's ``capture``, then a trusted fit worker runs the
task's ``evaluate`` on the captured data. Printed side by side, as medians over ``--repeats``
candidates (``--repeats // 3``, at least 1, where each one starts torch or Taichi afresh: a
fresh sandbox capturing a law, the Taichi timings):

- per candidate, in seconds (to the millisecond, the resolution of what the sandbox
  records): ``capture``, the capture step as the sandbox records it
  (``Evaluation.extras["capture_seconds"]``), ``rest`` (``Evaluation.seconds`` minus the
  capture: sending the data, the fit, its answer) and ``wall`` (the caller's wall time); for a
  candidate captured and evaluated directly in this process (no sandbox), in a warm pool (a
  one-slot :class:`~sga_agent.sandbox.SandboxPool` whose capture server and fit worker already
  run) and in a fresh :func:`~sga_agent.sandbox.evaluate_in_sandbox` (which starts both helpers
  for the candidate, so its capture includes starting the capture server and its rest starting
  the fit worker), each with the capture confined and not;
- for a trivial candidate (capture and fit do nothing), and for a constitutive law (capture:
  tracing the law into its graph, as the constitutive tasks do; fit: counting the graph's
  nodes): the elastic seed law;
- in a fresh fit worker (which no isolation setting changes): importing the constitutive
  task's modules (torch, Taichi, the bridges), ``taichi_mpm.init``, and the first and second
  run of a small forward simulation (the first loads its kernels from Taichi's offline cache).

Run ``taichi-mpm warmup`` first so that the cache holds the kernels. Usage::

    python benchmarks/sandbox_overhead.py [--repeats 10]
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sga_agent.isolation import detect_isolation
from sga_agent.sandbox import SandboxLimits, SandboxPool, evaluate_in_sandbox
from sga_agent.task import Evaluation, EvaluationSettings, PromptParts
from tasks.constitutive import prompt_text
from tasks.constitutive.task import ConstitutiveTask

HERE = Path(__file__).resolve().parent
TRIVIAL_TASK = "sandbox_overhead:TimingTask"
LAW_TASK = "sandbox_overhead:LawTimingTask"
SETTINGS = EvaluationSettings()


class TimingTask:
    """A trivial candidate: capture passes the text on; a fit of "taichi" times Taichi."""

    name = "timing"
    description = "Measures the sandbox's overhead (a benchmark task)."
    kind = "equation"

    def seed_solution(self) -> str:
        return "trivial"

    def prompt_parts(self) -> PromptParts:
        return PromptParts(role="", context="", template="", requirements="")

    def capture(self, solution: str) -> dict[str, Any]:
        return {"solution": solution}

    def evaluate(self, data: dict[str, Any], settings: EvaluationSettings) -> Evaluation:
        timings = taichi_timings() if data.get("solution") == "taichi" else {}
        return Evaluation(True, 0.0, "", extras=timings)


class LawTimingTask(TimingTask):
    """A constitutive law: captured as the constitutive tasks capture it (traced to a graph);
    the fit only counts the graph's nodes, so what is measured is the capture."""

    capture_modules = ConstitutiveTask.capture_modules

    def seed_solution(self) -> str:
        return prompt_text.ELASTIC_SEED

    def warm_up_solutions(self) -> list[str]:
        from tasks.constitutive.law_capture import WARM_UP_LAW

        return [prompt_text.ELASTIC_SEED, WARM_UP_LAW]

    def capture(self, solution: str) -> dict[str, Any]:
        from tasks.constitutive.law_capture import capture_law

        return {"law": capture_law(solution)}

    def evaluate(self, data: dict[str, Any], settings: EvaluationSettings) -> Evaluation:
        nodes = data.get("law", {}).get("nodes") if isinstance(data, dict) else None
        if not isinstance(nodes, list):
            return Evaluation.invalid("no graph was captured")
        return Evaluation(True, 0.0, "", extras={"nodes": len(nodes)})


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


def in_process(task: TimingTask, solution: str) -> Callable[[], dict[str, float]]:
    """Capture and evaluate called here, one after the other: no sandbox at all."""

    def measure() -> dict[str, float]:
        started = time.perf_counter()
        data = task.capture(solution)
        captured = time.perf_counter()
        checked(task.evaluate(data, SETTINGS))
        ended = time.perf_counter()
        return {"capture": captured - started, "rest": ended - captured, "wall": ended - started}

    return measure


def sandboxed(evaluate: Callable[[], Evaluation]) -> Callable[[], dict[str, float]]:
    """The capture step as the sandbox records it, the rest, and the caller's wall time."""

    def measure() -> dict[str, float]:
        started = time.perf_counter()
        evaluation = checked(evaluate())
        wall = time.perf_counter() - started
        capture = evaluation.extras["capture_seconds"]
        return {"capture": capture, "rest": evaluation.seconds - capture, "wall": wall}

    return measure


def checked(evaluation: Evaluation) -> Evaluation:
    if not evaluation.valid:
        raise RuntimeError(f"the benchmark task failed: {evaluation.reason}")
    return evaluation


def per_candidate(
    title: str, task: str, local: TimingTask, solution: str, repeats: int, fresh_repeats: int
) -> None:
    """One table: in this process, in warm pools and in fresh sandboxes, confined or not."""
    here = in_process(local, solution)
    here()  # imports what the capture needs (torch, for a law), untimed
    columns = {"in process": median_of(repeats, here)}
    for isolation in (False, True):
        limits = SandboxLimits(timeout_s=600, isolation=isolation)
        with SandboxPool(1, limits, extra_python_path=[HERE]) as pool:

            def warm() -> Evaluation:
                return pool.submit(task, solution, SETTINGS).result()

            checked(warm())  # starts the capture server and the fit worker, untimed
            name = "warm pool, isolated" if isolation else "warm pool"
            columns[name] = median_of(repeats, sandboxed(warm))
    for isolation in (False, True):
        cold = fresh(task, solution, SandboxLimits(timeout_s=600, isolation=isolation))
        name = "fresh, isolated" if isolation else "fresh"
        columns[name] = median_of(fresh_repeats, sandboxed(cold))
    show(title, columns)


def fresh(task: str, solution: str, limits: SandboxLimits) -> Callable[[], Evaluation]:
    """An evaluation that starts (and stops) its own capture server and fit worker."""

    def cold() -> Evaluation:
        return evaluate_in_sandbox(task, solution, SETTINGS, limits, extra_python_path=[HERE])

    return cold


def taichi_run() -> dict[str, float]:
    evaluation = checked(fresh(TRIVIAL_TASK, "taichi", SandboxLimits(timeout_s=600))())
    return {key: evaluation.extras[key] for key in ("import", "init", "first run", "second run")}


def show(title: str, columns: dict[str, dict[str, float]]) -> None:
    rows = list(next(iter(columns.values())))
    print(f"\n{title}")
    print(f"  {'seconds':<12}" + "".join(f"{name:>20}" for name in columns))
    for row in rows:
        print(f"  {row:<12}" + "".join(f"{column[row]:>20.3f}" for column in columns.values()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=10)
    args = parser.parse_args()
    if args.repeats < 1:
        raise SystemExit("--repeats must be at least 1")
    few = max(1, args.repeats // 3)
    isolation = detect_isolation()
    print("isolation:", *(f"  {key}: {value}" for key, value in vars(isolation).items()), sep="\n")
    checked(fresh(TRIVIAL_TASK, "trivial", SandboxLimits())())  # page the packages in
    per_candidate(
        f"a trivial candidate (median of {args.repeats})",
        TRIVIAL_TASK, TimingTask(), "trivial", args.repeats, args.repeats,
    )  # fmt: skip
    per_candidate(
        f"the elastic seed law, traced to its graph (median of {args.repeats}, {few} fresh)",
        LAW_TASK, LawTimingTask(), prompt_text.ELASTIC_SEED, args.repeats, few,
    )  # fmt: skip
    show(
        f"constitutive imports and Taichi in a fresh fit worker (median of {few})",
        {"fresh": median_of(few, taichi_run)},
    )


if __name__ == "__main__":
    main()
