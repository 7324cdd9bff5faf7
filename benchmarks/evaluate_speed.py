"""Time of one candidate evaluation of a constitutive-law task (paper scene, float32, CPU).

Each task runs in a fresh process (so its peak memory is its own): the ground-truth law
started 2x off is captured (in that process, as it is our own example law; untimed: see
``benchmarks/sandbox_overhead.py`` for the capture's cost) and fitted for ``--epochs`` epochs
(one epoch: the 1000-step teacher-forced forward pass and its segment-wise backward, with the
law rebuilt from its graph in the loop). Printed: the whole evaluation, the wall time per
epoch, the peak resident memory (and, as "base", the memory of the process once torch and
Taichi are loaded and started), and the ratio to the per-epoch times the issue reports for the
original authors' Warp + torch code on this machine (elastic 9-14 s, plasticine 17-23 s, about
2 GB). Usage::

    python benchmarks/evaluate_speed.py [--epochs 30] [--tasks elastic plasticine] [--profile]
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "scripts"))
from make_ground_truth import TWICE_OFF, truth_code  # noqa: E402

AUTHORS_SECONDS_PER_EPOCH = {"elastic": (9.0, 14.0), "plasticine": (17.0, 23.0)}


def law_code(task: str) -> str:
    """The task's ground-truth law with its parameters 2x off."""
    return truth_code(task, TWICE_OFF[task])


def run_one(task: str, epochs: int, profile: bool) -> dict:
    """Evaluate in this process (called in a child); returns the measurements."""
    import torch

    from sga_agent.registry import load_task
    from sga_agent.task import EvaluationSettings

    torch.set_num_threads(1)
    evaluator = load_task(task)
    from tasks.constitutive.evaluation import ensure_runtime

    ensure_runtime("float32")
    baseline_mb = _resident_mb()  # torch, Taichi and the project imported, Taichi started
    data = evaluator.capture(law_code(task))  # the law's graph: what the fit worker receives
    evaluator.evaluate(data, EvaluationSettings(epochs=0))  # compile, ground truth
    started = time.perf_counter()
    if profile:
        import cProfile
        import pstats

        profiler = cProfile.Profile()
        result = profiler.runcall(evaluator.evaluate, data, EvaluationSettings(epochs=epochs))
        pstats.Stats(profiler, stream=sys.stderr).sort_stats("tottime").print_stats(15)
    else:
        result = evaluator.evaluate(data, EvaluationSettings(epochs=epochs))
    seconds = time.perf_counter() - started
    return {
        "task": task,
        "valid": result.valid,
        "seconds": seconds,
        "epochs": epochs,
        "first_loss": result.curves["loss"][0] if result.valid else math.nan,
        # the last entry is the forward-only scoring of the final parameters
        "epoch_seconds": result.extras["epoch_seconds"][:-1],
        "loss": result.loss,
        "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "baseline_mb": baseline_mb,
    }


def _resident_mb() -> float:
    """Current resident memory (Linux /proc; the peak so far elsewhere)."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--epochs", type=int, default=30)
    parser.add_argument("--tasks", nargs="+", default=["elastic", "plasticine"], choices=TWICE_OFF)
    parser.add_argument("--profile", action="store_true", help="cProfile of the evaluation")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(run_one(args.child, args.epochs, args.profile)))
        return
    print(f"{'task':<11} {'epochs':>6} {'total s':>8} {'s/epoch':>8} {'peak MB':>8} {'base MB':>8} "
          f"{'loss start -> end':>22} {'authors s/epoch':>16} {'speed-up':>9}")  # fmt: skip
    for task in args.tasks:
        command = [sys.executable, __file__, "--child", task, "--epochs", str(args.epochs)]
        if args.profile:
            command.append("--profile")
        out = subprocess.run(command, capture_output=True, text=True, check=True)
        if args.profile:
            print(out.stderr)
        row = json.loads(out.stdout.strip().splitlines()[-1])
        per_epoch = sum(row["epoch_seconds"]) / max(len(row["epoch_seconds"]), 1)
        low, high = AUTHORS_SECONDS_PER_EPOCH.get(task, (math.nan, math.nan))
        authors = f"{low:.0f}-{high:.0f}" if math.isfinite(low) else "n/a"
        speedup = f"{low / per_epoch:.1f}-{high / per_epoch:.1f}x" if math.isfinite(low) else ""
        memory = f"{row['peak_mb']:8.0f} {row['baseline_mb']:8.0f}"
        losses = f"{row['first_loss']:10.2e} -> {row['loss']:9.2e}"
        print(f"{task:<11} {row['epochs']:>6} {row['seconds']:8.1f} {per_epoch:8.2f} {memory} "
              f"{losses} {authors:>16} {speedup:>9}")  # fmt: skip


if __name__ == "__main__":
    main()
