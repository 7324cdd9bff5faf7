"""How far float32 round-off alone moves a constitutive task's fitted loss.

Fits the task's true law from the start ``scripts/make_ground_truth.py --fit`` uses, and from
the same start with one value moved by a few float32 ulps (relative ``--nudges``). Where those
fits already end at different losses, a difference of that size between two commits is
round-off amplified by the optimizer, not a change of physics. Run it in each checkout to
compare (the code of the checkout on ``PYTHONPATH``)::

    python benchmarks/fit_round_off.py [--task imaginary] [--parameter log_weight_sand]
        [--nudges 0 3e-7 -3e-7]
    cd ../before && PYTHONPATH=. python /path/to/benchmarks/fit_round_off.py
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch

from sga_agent.registry import load_task
from sga_agent.task import EvaluationSettings
from tasks.constitutive.options import ConstitutiveOptions


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="imaginary")
    parser.add_argument("--parameter", default="log_weight_sand", help="the value nudged")
    parser.add_argument("--nudges", type=float, nargs="+", default=[0.0, 3e-7, -3e-7])
    args = parser.parse_args()
    sys.path.insert(0, str(Path.cwd() / "scripts"))  # the checkout's own make_ground_truth
    import make_ground_truth as truths

    torch.set_num_threads(1)
    # a checkout from before typed options (no options_as) gave the task a dict
    options = ConstitutiveOptions() if hasattr(EvaluationSettings, "options_as") else {}
    for nudge in args.nudges:
        start = dict(truths.TWICE_OFF[args.task])
        start[args.parameter] *= 1 + nudge
        started = time.perf_counter()
        code = truths.truth_code(args.task, start)
        fit = truths.score(load_task(args.task), code, EvaluationSettings(options=options), "")
        print(f"nudge {nudge:+.0e}: start loss {fit.curves['loss'][0]:.6e}, fitted {fit.loss:.4e}"
              f" (best epoch {fit.extras['best_epoch']}, {time.perf_counter() - started:.0f} s)",
              flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
