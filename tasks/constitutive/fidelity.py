"""The cheaper fit of a multi-fidelity search's screen (``EvaluationSettings.fidelity`` < 1):
that share of the epochs on that share of the observation's first teacher-forced segments.

A fit at fidelity f runs ``ceil(f * epochs)`` epochs (at least one where the full fit has
any) on the first ``ceil(f * segments)`` segments (at least one): at f = 0.2 and the quick
preset's 5 epochs of the 10-segment scene, one epoch on 2 segments. Its loss is a mean over
fewer steps, so it is comparable only with losses of the same fidelity.
"""

from __future__ import annotations

import math

from tasks.constitutive.ground_truth import Trajectory


def screen_epochs(epochs: int, fidelity: float) -> int:
    """The epochs of a fit at ``fidelity`` whose full fit runs ``epochs``."""
    if fidelity >= 1 or epochs == 0:
        return epochs
    return max(1, math.ceil(fidelity * epochs))


def segments(observed: Trajectory, reset_every: int) -> int:
    """How many segments of ``reset_every`` steps the observation's horizon holds."""
    return math.ceil((observed.positions.shape[0] - 1) / reset_every)


def first_segments(observed: Trajectory, reset_every: int, fidelity: float) -> Trajectory:
    """The observation cut to its first ``ceil(fidelity * segments)`` segments (itself when
    that is all of them): positions and reset states alike."""
    total = segments(observed, reset_every)
    kept = max(1, math.ceil(fidelity * total))
    if kept >= total:
        return observed
    end = kept * reset_every
    states = observed.states
    return Trajectory(
        positions=observed.positions[: end + 1],
        reset_steps=observed.reset_steps[:kept],
        states=None if states is None else {name: value[:kept] for name, value in states.items()},
    )
