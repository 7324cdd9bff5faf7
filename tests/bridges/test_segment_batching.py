"""Teacher-forced segments run as one batch of scene copies give the sequential result.

For every law of bridges.laws (the materials of the equivalence test), the loss, the positions
and the gradient of every parameter with segments batched equal those with one segment at a time
(float64, 1e-10 relative), with and without teacher forcing, and with a short last segment.
"""

import gc

import numpy as np
import pytest
import torch

import taichi_mpm as tm
from bridges.laws import from_material, parameter_gradients
from bridges.rollout import (
    LawError,
    Rollout,
    State,
    _groups,
    _SquaredError,
    segments_per_batch,
    trajectory_loss,
)
from tests.bridges.test_equivalence import MATERIALS
from tests.taichi_mpm.helpers import impact_scene

STEPS, SEGMENT = 70, 20  # segments start at 0, 20, 40, 60; the last is 10 steps


def _observation(material: tm.Material):
    """A noisy trajectory of another material, with the reset states of ``material``."""
    scene = impact_scene(steps=STEPS)
    sim = tm.Simulator(scene, material)
    sim.forward(state_frames=list(range(0, STEPS, SEGMENT)))
    resets = dict(sim.states)
    stiffer = tm.Simulator(scene, tm.Material(tm.NeoHookean(3e5, 0.25), tm.NoPlasticity()))
    observed = stiffer.forward()
    observed = observed + 1e-3 * np.random.default_rng(2).standard_normal(observed.shape)
    return scene, observed, resets


def _fit_gradients(material, scene, observed, resets, batch):
    plastic, elastic = from_material(material, dtype=torch.float64)
    result = trajectory_loss(
        Rollout(scene, plastic, elastic), observed, resets, segment=SEGMENT, batch=batch
    )
    return result, parameter_gradients(plastic, elastic)


@pytest.mark.slow
@pytest.mark.parametrize("teacher_forcing", [True, False], ids=["teacher", "free"])
@pytest.mark.parametrize("name", list(MATERIALS))
def test_batched_segments_equal_sequential_ones(name, teacher_forcing):
    material = MATERIALS[name]
    scene, observed, resets = _observation(material)
    resets = resets if teacher_forcing else None
    sequential, expected = _fit_gradients(material, scene, observed, resets, batch=1)
    batched, got = _fit_gradients(material, scene, observed, resets, batch=3)

    assert batched.loss == pytest.approx(sequential.loss, rel=1e-10)
    np.testing.assert_allclose(batched.positions, sequential.positions, rtol=0, atol=1e-12)
    assert set(got) == set(expected) and expected
    for parameter, value in expected.items():
        assert got[parameter] == pytest.approx(value, rel=1e-10, abs=1e-14 * abs(value) + 1e-300), (
            parameter
        )


def test_copies_of_a_batch_do_not_interact():
    """Two different states stepped as one batch move exactly as each does alone."""
    material = MATERIALS["neo_hookean"]
    scene = impact_scene(steps=5)
    plastic, elastic = from_material(material, dtype=torch.float64)
    rollout = Rollout(scene, plastic, elastic)
    first = State.initial(scene, torch.float64)
    second = State(first.x.flip(0) * 0.9 + 0.05, -first.v, first.C, first.F)
    with torch.no_grad():
        alone = [rollout.run(state, 5) for state in (first, second)]
        together = rollout.run(State.stacked([first, second]), 5, batch=2)
    for got, want in zip(together.tensors(), State.stacked(alone).tensors(), strict=True):
        assert torch.equal(got, want)


def test_segments_are_grouped_by_length_and_batch():
    starts = list(range(0, 70, 20))
    assert _groups(starts, 70, 20, 3) == [[0, 1, 2], [3]]
    assert _groups(starts, 70, 20, 2) == [[0, 1], [2], [3]]
    assert _groups(list(range(0, 80, 20)), 80, 20, 10) == [[0, 1, 2, 3]]
    assert _groups(starts, 70, 20, 1) == [[0], [1], [2], [3]]
    # as few runs as the batch allows, as even as they can be
    assert _groups(list(range(0, 100, 10)), 100, 10, 6) == [[0, 1, 2, 3, 4], [5, 6, 7, 8, 9]]
    assert _groups(list(range(0, 100, 10)), 100, 10, 4) == [[0, 1, 2, 3], [4, 5, 6, 7], [8, 9]]


class _MeanOverParticles(torch.nn.Module):
    def forward(self, F):
        return F - F.mean(dim=0, keepdim=True) + torch.eye(3, dtype=F.dtype)


class _OrderedByParticle(torch.nn.Module):
    def forward(self, F):
        ramp = torch.linspace(0.0, 1e-3, F.shape[0], dtype=F.dtype).view(-1, 1, 1)
        return F * (1.0 + ramp)


@pytest.mark.parametrize("law", [_MeanOverParticles(), _OrderedByParticle()])
def test_a_law_that_mixes_particles_is_refused(law):
    scene = impact_scene(steps=3)
    _, elastic = from_material(MATERIALS["neo_hookean"], dtype=torch.float64)
    rollout = Rollout(scene, law, elastic)
    observed = np.repeat(scene.positions[None], 4, axis=0)
    with pytest.raises(LawError, match="the plastic law mixes particles"):
        trajectory_loss(rollout, observed, segment=3)


def test_the_batch_size_follows_the_measured_graph_memory():
    material = MATERIALS["von_mises"]
    scene, _, resets = _observation(material)
    plastic, elastic = from_material(material, dtype=torch.float64)
    rollout = Rollout(scene, plastic, elastic)
    start = State.from_arrays(resets, 0, torch.float64)
    one = segments_per_batch(rollout, start, SEGMENT, 2**40)  # bytes of one segment: 2**40 / one
    per_segment = 2**40 // one
    # half a segment of slack: a second measurement may differ slightly from the first
    assert segments_per_batch(rollout, start, SEGMENT, int(3.5 * per_segment)) == 3
    assert segments_per_batch(rollout, start, SEGMENT, 0) == 1


@pytest.mark.parametrize("name", ["von_mises", "neo_hookean"])
def test_the_measured_segment_memory_is_what_a_segment_keeps(name):
    """The budget's measurement counts what autograd keeps for a real segment: a step measured
    from an input without a gradient would miss the laws' operations before their first
    parameter (the SVD of F_trial) and let batches outgrow the budget."""
    material = MATERIALS[name]
    scene, observed, resets = _observation(material)
    plastic, elastic = from_material(material, dtype=torch.float64)
    rollout = Rollout(scene, plastic, elastic)
    start = State.from_arrays(resets, 0, torch.float64)
    measured = 2**40 / segments_per_batch(rollout, start, SEGMENT, 2**40)

    kept: dict[int, int] = {}

    def count(tensor: torch.Tensor) -> torch.Tensor:
        storage = tensor.untyped_storage()
        kept[storage.data_ptr()] = storage.nbytes()
        return tensor

    with torch.autograd.graph.saved_tensors_hooks(count, lambda tensor: tensor):
        trajectory_loss(rollout, observed[: SEGMENT + 1], resets, segment=SEGMENT, backward=True)
    assert 0.9 * sum(kept.values()) <= measured <= 1.15 * sum(kept.values())


def test_a_group_of_segments_is_freed_before_the_next_one_runs():
    """The steps of one batch of segments (their autograd nodes, and the packed outputs those
    hold) are gone when the next batch takes its first step: memory holds one batch's graph."""
    material = MATERIALS["neo_hookean"]
    scene, observed, resets = _observation(material)
    plastic, elastic = from_material(material, dtype=torch.float64)
    rollout = Rollout(scene, plastic, elastic)
    live_at_step: list[int] = []
    step = rollout.step

    def counting_step(state, batch=1):
        gc.collect()
        live_at_step.append(sum(type(o).__name__ == "_MPMStepBackward" for o in gc.get_objects()))
        return step(state, batch)

    rollout.step = counting_step
    trajectory_loss(rollout, observed, resets, segment=SEGMENT, batch=2)
    # groups: segments 0-1 (20 steps, batch 2), then the short last one alone
    assert live_at_step[0] == 0 and live_at_step[19] == 19
    assert live_at_step[20] == 0, "the first group's steps outlive its backward pass"


def test_squared_error_gradient_matches_finite_differences():
    """The step's loss term differentiates its positions exactly (the observed frame of each
    copy from its own row)."""
    generator = torch.Generator().manual_seed(3)
    observed = torch.randn(6, 4, 3, generator=generator, dtype=torch.float64)
    x = torch.randn(8, 3, generator=generator, dtype=torch.float64, requires_grad=True)
    rows = torch.tensor([1, 4])  # two copies of a 4-particle scene

    def error(x):
        return _SquaredError.apply(x, observed, rows)

    assert torch.autograd.gradcheck(error, (x,))
    expected = ((x - observed[rows].reshape(8, 3)) ** 2).sum()
    assert error(x).item() == pytest.approx(expected.item(), rel=1e-14)
