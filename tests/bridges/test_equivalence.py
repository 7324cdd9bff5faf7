"""The bridge's main test: torch laws through the bridge equal taichi_mpm's built-in laws.

For every built-in material, the same law written in torch (bridges.laws) and run through
bridges.rollout gives the trajectory of taichi_mpm.Simulator (1e-5 relative, float64) and the
same gradients of every material parameter (1e-4 relative).
"""

import numpy as np
import pytest
import torch

import taichi_mpm as tm
from bridges.laws import from_material, parameter_gradients
from bridges.rollout import Frames, Rollout, State, trajectory_loss
from tests.taichi_mpm.helpers import impact_scene

STEPS = 80
ELASTIC = {
    "linear": tm.LinearElastic(E=1e5, nu=0.3),
    "corotated": tm.FixedCorotated(E=1e5, nu=0.3),
    "neo_hookean": tm.NeoHookean(E=1e5, nu=0.3),
    "stvk_hencky": tm.StVKHencky(E=1e5, nu=0.3),
}
PLASTIC = {
    "von_mises": tm.VonMises(yield_stress=2e3),
    "sand": tm.DruckerPrager(friction_angle=30.0, cohesion=0.01),
    "fluid": tm.WeaklyCompressibleFluid(),
    "mixture": tm.PlasticMixture(
        [
            (0.5, tm.VonMises(2e3)),
            (0.3, tm.DruckerPrager(30.0)),
            (0.2, tm.WeaklyCompressibleFluid()),
        ]
    ),
}
MATERIALS = {name: tm.Material(law, tm.NoPlasticity()) for name, law in ELASTIC.items()}
MATERIALS.update(
    {name: tm.Material(ELASTIC["stvk_hencky"], law) for name, law in PLASTIC.items()}
)


def _observed(scene: tm.Scene) -> np.ndarray:
    """A trajectory to compare with: a stiffer neo-Hookean body."""
    sim = tm.Simulator(scene, tm.Material(tm.NeoHookean(3e5, 0.25), tm.NoPlasticity()))
    return sim.forward()


@pytest.mark.slow
@pytest.mark.parametrize("name", list(MATERIALS))
def test_torch_laws_through_the_bridge_equal_taichi_mpm(name):
    material = MATERIALS[name]
    scene = impact_scene(steps=STEPS)
    observed = _observed(scene)
    sim = tm.Simulator(scene, material)
    positions = sim.forward()
    plastic, elastic = from_material(material, dtype=torch.float64)
    rollout = Rollout(scene, plastic, elastic)
    result = trajectory_loss(rollout, observed, segment=30)  # checkpointed, no teacher forcing

    scale = np.abs(positions - positions[0]).max()
    assert np.abs(result.positions - positions).max() < 1e-5 * scale

    scale_factor = 1.0 / (STEPS * scene.num_particles * 3)
    expected_loss = ((positions[1:] - observed[1:]) ** 2).sum() * scale_factor
    assert result.loss == pytest.approx(expected_loss, rel=1e-8)
    seed = 2.0 * (positions - observed) * scale_factor
    seed[0] = 0.0
    expected = sim.backward(seed).material
    got = parameter_gradients(plastic, elastic)
    assert set(expected) <= set(got)
    for parameter, value in expected.items():
        assert got[parameter] == pytest.approx(value, rel=1e-4, abs=1e-12 * abs(value) + 1e-30), (
            parameter
        )


@pytest.mark.slow
def test_segments_and_teacher_forcing_are_consistent():
    """Checkpointed backward equals one-segment backward; teacher forcing at the true state
    changes nothing for the law that generated the observation."""
    material = MATERIALS["von_mises"]
    scene = impact_scene(steps=STEPS)
    sim = tm.Simulator(scene, material)
    observed = sim.forward(state_frames=[0, 40])
    resets = dict(sim.states)
    observed = observed + 1e-3 * np.random.default_rng(1).standard_normal(observed.shape)

    grads = []
    for kwargs in ({"segment": STEPS}, {"segment": 25}, {"segment": 40, "resets": resets}):
        plastic, elastic = from_material(material, dtype=torch.float64)
        result = trajectory_loss(Rollout(scene, plastic, elastic), observed, **kwargs)
        grads.append((result.loss, parameter_gradients(plastic, elastic)))
    (loss_a, a), (loss_b, b), (loss_c, c) = grads
    assert loss_b == pytest.approx(loss_a, rel=1e-12)
    assert loss_c == pytest.approx(loss_a, rel=1e-9)
    for key in a:
        assert b[key] == pytest.approx(a[key], rel=1e-10)
        # teacher forcing cuts the gradient path across the reset: only the loss agrees
    assert c["yield_stress"] != pytest.approx(a["yield_stress"], rel=1e-3, abs=0)


def test_frames_of_some_steps_and_particles_equal_taichi_mpm():
    """A loss on a few frames of a third of the particles (:class:`Frames`, checkpointed
    segments that hold no frame among them) has taichi_mpm's loss and material gradients for
    the same positions weighted alike, and the simulated positions at those frames."""
    material = MATERIALS["von_mises"]
    scene = impact_scene(steps=STEPS)
    steps, particles = np.array([7, 30, 55, STEPS]), np.arange(0, scene.num_particles, 3)
    observed = _observed(scene)[np.ix_(steps, particles)]
    sim = tm.Simulator(scene, material)
    positions = sim.forward()
    plastic, elastic = from_material(material, dtype=torch.float64)
    result = trajectory_loss(Rollout(scene, plastic, elastic), Frames(steps, observed, particles),
                             segment=20)  # fmt: skip

    simulated = positions[np.ix_(steps, particles)]
    scale = np.abs(positions - positions[0]).max()
    assert result.positions.shape == observed.shape
    assert np.abs(result.positions - simulated).max() < 1e-5 * scale
    factor = 1.0 / observed.size
    assert result.loss == pytest.approx(((simulated - observed) ** 2).sum() * factor, rel=1e-8)
    seed = np.zeros_like(positions)
    seed[np.ix_(steps, particles)] = 2.0 * (simulated - observed) * factor
    expected = sim.backward(seed).material
    got = parameter_gradients(plastic, elastic)
    for parameter, value in expected.items():
        assert got[parameter] == pytest.approx(value, rel=1e-4, abs=1e-12 * abs(value) + 1e-30), (
            parameter
        )


def test_step_gradients_match_finite_differences():
    """The autograd Function's input gradients (x, v, C, F, stress) against central differences."""
    scene = impact_scene(steps=1)
    material = MATERIALS["neo_hookean"]
    plastic, elastic = from_material(material, dtype=torch.float64)
    rollout = Rollout(scene, plastic, elastic)
    state = State.initial(scene, torch.float64)
    rng = np.random.default_rng(3)
    F = torch.eye(3, dtype=torch.float64) + 0.05 * torch.tensor(rng.standard_normal((64, 3, 3)))
    C = 2.0 * torch.tensor(rng.standard_normal((64, 3, 3)))
    stress = 1e3 * torch.tensor(rng.standard_normal((64, 3, 3)))
    inputs = [state.x.clone(), state.v.clone(), C, F, stress]
    weights = [torch.tensor(rng.standard_normal(t.shape)) for t in (inputs[0], inputs[1], C, F)]

    from bridges.step import mpm_step

    def objective(*args):
        outputs = mpm_step(*args, rollout.transfer)
        return sum((w * o).sum() for w, o in zip(weights, outputs, strict=True))

    leaves = [t.clone().requires_grad_(True) for t in inputs]
    objective(*leaves).backward()
    for index, leaf in enumerate(leaves):
        direction = torch.tensor(rng.standard_normal(leaf.shape))
        h = 1e-6 * max(1.0, float(inputs[index].abs().max()))
        plus = [t.clone() for t in inputs]
        minus = [t.clone() for t in inputs]
        plus[index] = plus[index] + h * direction
        minus[index] = minus[index] - h * direction
        numeric = (objective(*plus) - objective(*minus)).item() / (2 * h)
        analytic = float((leaf.grad * direction).sum())
        assert analytic == pytest.approx(numeric, rel=1e-5, abs=1e-7), index
