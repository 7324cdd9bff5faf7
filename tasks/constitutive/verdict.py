"""Whether a run's best law reproduces the observed motion, said in words.

Light (no torch, no Taichi). The judges are the free runs (no teacher forcing) on the held-out
scene, where there is one, and on the training scene: their RMS position errors at the end, in
body sizes, against :data:`THRESHOLDS` (the end, where a law's errors have added up: over a
short scene the average hides them). A law reproduces the motion when every one is within.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from tasks.constitutive.free_run import FreeRun


@dataclass(frozen=True)
class Thresholds:
    """``reproduces``: the largest free-run error (RMS position error at the end, in body
    sizes) of a law that reproduces the motion. 5 % leaves room for an observation's noise
    (1 % of the body size per coordinate is 1.7 % RMS) and float32. On the full held-out
    scene (600 steps, float32) every task's true law ends within 2e-4, its seed 72 % to 140 %
    off (``python -m tasks.constitutive.held_out`` prints them)."""

    reproduces: float = 0.05


THRESHOLDS = Thresholds()
#: What to try when the best law does not reproduce the motion.
ADVICE = "try a longer --time-budget or a model"


def verdict(
    held_out: FreeRun | None, training: FreeRun | None, thresholds: Thresholds = THRESHOLDS
) -> str:
    """One sentence: whether the best law reproduces the motion, on the held-out scene and on
    the training scene, each within ``thresholds.reproduces`` ("" without a free run)."""
    runs = [(run, where) for run, where in ((held_out, "the held-out scene"),
                                            (training, "the training scene")) if run]  # fmt: skip
    if not runs:
        return ""
    unstable = [where for run, where in runs if run.unstable or not math.isfinite(run.final_error)]
    if unstable:
        return (f"the best law does not reproduce the motion: its free run on {unstable[0]} is "
                f"unstable; {ADVICE}")  # fmt: skip
    errors = ", ".join(
        f"{_percent(run.final_error)} free-run error on {where}" if index == 0
        else f"{_percent(run.final_error)} on {where}"
        for index, (run, where) in enumerate(runs)
    )  # fmt: skip
    limit = f"{_percent(thresholds.reproduces)} at most" + (" on each" if len(runs) > 1 else "")
    if all(run.final_error <= thresholds.reproduces for run, _ in runs):
        return f"the best law reproduces the motion: {errors} ({limit})"
    return f"the best law does not reproduce the motion: {errors} ({limit}); {ADVICE}"


def _percent(fraction: float) -> str:
    return f"{100 * fraction:.2g} %"
