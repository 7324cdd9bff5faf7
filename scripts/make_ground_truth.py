"""Generate (and cache) the ground-truth trajectories of the constitutive-law tasks.

For each task it also scores, without fitting, the task's seed law and the ground-truth law
written in torch (``examples/laws``): the seed must score clearly worse than the truth, which
scores at float32 noise level. With ``--fit`` it then starts the ground-truth law with its
parameters 2x off and runs the task's inner optimization (the paper's Adam, learning rate 3e-2,
30 epochs; L-BFGS with 31 evaluations for `imaginary`), reporting the loss before and after.
Each law goes through the task's two steps, capture (its graph) then evaluate (the fit), both
in this process: the laws are this project's own, so they need no sandbox. Usage::

    python scripts/make_ground_truth.py [--tasks elastic plasticine ...] [--steps 1000] [--fit]
"""

from __future__ import annotations

import argparse
import math
import re
import time
from pathlib import Path

import torch

from sga_agent.registry import load_task
from sga_agent.task import Evaluation, EvaluationSettings, InvalidSolution, Task
from tasks.constitutive.options import ConstitutiveOptions
from tasks.constitutive.specs import SPECS

LAWS = Path(__file__).resolve().parent.parent / "examples" / "laws"
TRUTH_FILES = {
    "elastic": "neo_hookean.py",
    "plasticine": "von_mises.py",
    "granular": "drucker_prager.py",
    "fluid": "fluid.py",
    "imaginary": "mixture.py",
}
#: Parameters of the ground-truth laws 2x off (nu halved: doubling it leaves (-1, 0.5); the
#: mixture's weights halved or doubled but still summing to 1, as a mixture's do).
TWICE_OFF = {
    "elastic": {"log_youngs_modulus": 13.0 + math.log(2.0), "poissons_ratio": 0.1225},
    "plasticine": {"log_yield_stress": math.log(6e4)},
    "granular": {"log_friction_angle": math.log(50.0)},
    "fluid": {"fluidity": 0.5},
    "imaginary": {
        "log_weight_von_mises": math.log(0.25),
        "log_weight_sand": math.log(0.6),
        "log_weight_fluid": math.log(0.15),
        # halved, not doubled: at 6e4 the mixture's von Mises part never yields in the scene,
        # so the loss is flat in the yield stress and no gradient method can recover it
        "log_yield_stress": math.log(1.5e4),
        "log_friction_angle": math.log(50.0),
    },
}


def truth_code(task: str, start: dict[str, float] | None = None) -> str:
    """The ground-truth law of ``task``, with the defaults of ``start`` substituted."""
    code = (LAWS / TRUTH_FILES[task]).read_text()
    for argument, value in (start or {}).items():
        code, count = re.subn(rf"({argument}: float = )[^,)\n]+", rf"\g<1>{value!r}", code)
        if count != 1:
            raise ValueError(f"{TRUTH_FILES[task]} has no default for {argument!r}")
    return code


def score(task: Task, code: str, settings: EvaluationSettings, label: str) -> Evaluation:
    """Capture ``code`` (one of our own laws, so in this process) and fit the captured law."""
    try:
        data = task.capture(code)
    except InvalidSolution as error:
        raise SystemExit(f"{task.name}: the {label} law could not be captured: {error}") from None
    return task.evaluate(data, settings)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", nargs="+", default=list(SPECS), choices=list(SPECS))
    parser.add_argument("--steps", type=int, default=None, help="shorter scene (default: task's)")
    parser.add_argument("--fit", action="store_true", help="fit the truth started 2x off")
    args = parser.parse_args()
    torch.set_num_threads(1)
    options = ConstitutiveOptions(steps=args.steps)
    settings = EvaluationSettings(epochs=0, options=options)
    print(f"{'task':<11} {'seed loss':>11} {'truth loss':>11} {'ratio':>9} {'seconds':>8}")
    for name in args.tasks:
        task = load_task(name)
        started = time.perf_counter()
        seed = score(task, task.seed_solution(), settings, "seed")
        truth = score(task, truth_code(name), settings, "truth")
        for label, result in (("seed", seed), ("truth", truth)):
            if not result.valid:
                raise SystemExit(f"{name}: the {label} law is invalid: {result.reason}")
        ratio = seed.loss / max(truth.loss, 1e-30)
        print(f"{name:<11} {seed.loss:11.3e} {truth.loss:11.3e} {ratio:9.1e} "
              f"{time.perf_counter() - started:8.1f}")  # fmt: skip
    if args.fit:
        print(f"\n{'task':<11} {'start loss':>11} {'fitted':>11} {'ratio':>9} {'best epoch':>10} "
              f"{'seconds':>8}  fitted parameters")  # fmt: skip
        for name in args.tasks:
            started = time.perf_counter()
            code = truth_code(name, TWICE_OFF[name])
            fit = score(load_task(name), code, EvaluationSettings(options=options), "2x-off truth")
            if not fit.valid:
                raise SystemExit(f"{name}: the fit failed: {fit.reason}")
            first = fit.curves["loss"][0]
            values = ", ".join(f"{key}={value:.4g}" for key, value in fit.parameters.items())
            print(f"{name:<11} {first:11.3e} {fit.loss:11.3e} {first / fit.loss:9.1e} "
                  f"{fit.extras['best_epoch']:>10} {time.perf_counter() - started:8.1f}  "
                  f"{values}")  # fmt: skip


if __name__ == "__main__":
    main()
