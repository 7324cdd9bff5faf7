"""Whether a run's best law reproduces the observed motion, said in words.

Light (no torch, no Taichi). The judge is the free run (no teacher forcing) on the held-out
scene when there is one, else on the training scene: its RMS position error at the end, in
body sizes, against :data:`THRESHOLDS` (the end, where a law's errors have added up: over a
short scene the average hides them).
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
    """One sentence: whether the best law reproduces the motion ("" without a free run)."""
    run, where = (held_out, "the held-out scene") if held_out else (training, "the training scene")
    if run is None:
        return ""
    limit = f"{_percent(thresholds.reproduces)} at most"
    if run.unstable or not math.isfinite(run.final_error):
        return (f"the best law does not reproduce the motion: its free run on {where} is "
                f"unstable; {ADVICE}")  # fmt: skip
    error = f"{_percent(run.final_error)} free-run error on {where} ({limit})"
    if run.final_error <= thresholds.reproduces:
        return f"the best law reproduces the motion: {error}"
    return f"the best law does not reproduce the motion: {error}; {ADVICE}"


def _percent(fraction: float) -> str:
    return f"{100 * fraction:.2g} %"
