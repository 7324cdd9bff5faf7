"""The checkpointed gradient's segment length follows its memory budget, and a simulation keeps
only the steps asked for.

:func:`bridges.rollout.checkpoint_segment` picks the longest segment whose graph (steps of the
measured step graph) and checkpoints (a state per segment) fit the budget; a budget no length
fits is refused with what it would need. The loss and gradient do not depend on the length.
"""

import numpy as np
import pytest
import torch

from bridges.laws import from_material, parameter_gradients
from bridges.rollout import (
    Frames,
    GraphBudgetError,
    Rollout,
    State,
    checkpoint_segment,
    step_graph_bytes,
    trajectory_loss,
)
from tests.bridges.test_equivalence import MATERIALS
from tests.taichi_mpm.helpers import impact_scene

STEPS = 60


def _rollout(steps: int = STEPS) -> Rollout:
    plastic, elastic = from_material(MATERIALS["von_mises"], dtype=torch.float64)
    return Rollout(impact_scene(steps=steps), plastic, elastic)


def _sizes(rollout: Rollout) -> tuple[int, int]:
    state = State.initial(rollout.scene, rollout.dtype)
    return step_graph_bytes(rollout, state), sum(t.nbytes for t in state.tensors())


def test_the_segment_is_the_longest_that_fits_the_budget():
    rollout = _rollout()
    per_step, per_state = _sizes(rollout)

    def needed(length: int) -> int:
        return length * per_step + -(-STEPS // length) * per_state

    for length in (5, 12, 30):
        budget = needed(length)
        chosen, used = checkpoint_segment(rollout, STEPS, budget, longest=STEPS)
        assert used <= budget
        assert chosen >= length and needed(chosen + 1) > budget or chosen == STEPS
    assert checkpoint_segment(rollout, STEPS, 10**12, longest=25) == (25, needed(25))
    doubled, used = checkpoint_segment(rollout, STEPS, 2 * needed(12), STEPS, slack=2.0)
    assert (doubled, used) == (checkpoint_segment(rollout, STEPS, needed(12), STEPS)[0],
                               2 * needed(doubled))  # fmt: skip


def test_a_budget_no_segment_fits_is_refused_with_what_it_needs():
    rollout = _rollout()
    per_step, per_state = _sizes(rollout)
    least = min(length * per_step + -(-STEPS // length) * per_state for length in range(1, 61))
    refusal = r"needs [\d.]+ MiB at least .* budget of [\d.]+ MiB"
    with pytest.raises(GraphBudgetError, match=refusal):
        checkpoint_segment(rollout, STEPS, least - 1, longest=STEPS)


def test_the_gradient_does_not_depend_on_the_segment_length():
    scene = impact_scene(steps=STEPS)
    steps = np.array([10, 33, STEPS])
    observed = Rollout(scene, *from_material(MATERIALS["neo_hookean"], torch.float64)).simulate(
        kept=steps
    )
    results = []
    for segment in (1, 7, STEPS):
        rollout = _rollout()
        loss = trajectory_loss(rollout, Frames(steps, observed + 0.01), segment=segment).loss
        results.append((loss, parameter_gradients(rollout.plastic, rollout.elastic)))
    (loss, expected), *others = results
    for other_loss, got in others:
        assert other_loss == pytest.approx(loss, rel=1e-12)
        for name, value in expected.items():
            assert got[name] == pytest.approx(value, rel=1e-9, abs=1e-30), name


def test_a_simulation_keeps_the_steps_asked_for():
    rollout = _rollout(steps=12)
    every = rollout.simulate()
    kept = rollout.simulate(kept=np.array([0, 5, 12]))
    assert np.array_equal(kept, every[[0, 5, 12]])
    assert np.array_equal(rollout.simulate(kept=np.array([3])), every[[3]])
    with pytest.raises(ValueError, match=r"kept steps must lie in \[0, 12\]"):
        rollout.simulate(kept=np.array([4, 13]))
