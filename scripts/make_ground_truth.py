"""Generate (and cache) the ground-truth trajectories of the constitutive-law tasks.

For each task it also scores, without fitting, the task's seed law and the ground-truth law
written in torch (``examples/laws``): the seed must score clearly worse than the truth, which
scores at float32 noise level. Usage::

    python scripts/make_ground_truth.py [--tasks elastic plasticine ...] [--steps 1000]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import torch

from sga_agent.registry import load_task
from sga_agent.task import EvaluationSettings
from tasks.constitutive.specs import SPECS

LAWS = Path(__file__).resolve().parent.parent / "examples" / "laws"
TRUTH_FILES = {
    "elastic": "neo_hookean.py",
    "plasticine": "von_mises.py",
    "granular": "drucker_prager.py",
    "fluid": "fluid.py",
    "imaginary": "mixture.py",
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", nargs="+", default=list(SPECS), choices=list(SPECS))
    parser.add_argument("--steps", type=int, default=None, help="shorter scene (default: task's)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    options = {} if args.steps is None else {"steps": args.steps}
    settings = EvaluationSettings(epochs=0, options=options)
    print(f"{'task':<11} {'seed loss':>11} {'truth loss':>11} {'ratio':>9} {'seconds':>8}")
    for name in args.tasks:
        task = load_task(name)
        started = time.perf_counter()
        seed = task.evaluate(task.seed_solution(), settings)
        truth = task.evaluate((LAWS / TRUTH_FILES[name]).read_text(), settings)
        for label, result in (("seed", seed), ("truth", truth)):
            if not result.valid:
                raise SystemExit(f"{name}: the {label} law is invalid: {result.reason}")
        ratio = seed.loss / max(truth.loss, 1e-30)
        print(f"{name:<11} {seed.loss:11.3e} {truth.loss:11.3e} {ratio:9.1e} "
              f"{time.perf_counter() - started:8.1f}")  # fmt: skip


if __name__ == "__main__":
    main()
