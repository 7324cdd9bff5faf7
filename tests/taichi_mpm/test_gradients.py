"""Reverse-mode gradients against central finite differences (float64)."""

import numpy as np
import pytest

import taichi_mpm as tm
from tests.taichi_mpm.helpers import impact_scene, weighted_loss

MATERIALS = {
    "linear": tm.Material(tm.LinearElastic(E=2e4, nu=0.3)),
    "corotated": tm.Material(tm.FixedCorotated(E=2e4, nu=0.3)),
    "neo_hookean": tm.Material(tm.NeoHookean(E=2e4, nu=0.3)),
    "stvk_hencky": tm.Material(tm.StVKHencky(E=2e4, nu=0.3)),
    "von_mises": tm.Material(tm.StVKHencky(E=2e4, nu=0.3), tm.VonMises(yield_stress=1.5e3)),
    "sand": tm.Material(
        tm.StVKHencky(E=2e4, nu=0.3), tm.DruckerPrager(friction_angle=30.0, cohesion=0.01)
    ),
    "fluid": tm.Material(tm.StVKHencky(E=2e4, nu=0.3), tm.WeaklyCompressibleFluid()),
    "mixture": tm.Material(
        tm.NeoHookean(E=2e4, nu=0.3),
        tm.PlasticMixture(
            [
                (0.5, tm.VonMises(1.5e3)),
                (0.3, tm.DruckerPrager(5.0, cohesion=0.01)),
                (0.2, tm.WeaklyCompressibleFluid()),
            ]
        ),
    ),
}

FRAMES = [20, 40, 60]
# Plastic yield surfaces make the loss piecewise smooth: a large step may cross a kink,
# a small one drowns in round-off. The gradient must match the central difference at
# one of these relative steps.
RELATIVE_STEPS = (1e-5, 1e-6, 1e-7)


def loss_of(scene, material) -> float:
    sim = tm.Simulator(scene, material, checkpoint_every=25)
    return weighted_loss(sim.forward(FRAMES))[0]


def relative_error(analytic: float, numeric: float) -> float:
    return abs(analytic - numeric) / max(abs(numeric), abs(analytic), 1e-300)


def assert_matches_central_difference(analytic: float, loss_at, scale: float, name: str) -> None:
    """loss_at(h) is the loss at parameter + h; compare against (L(+h) - L(-h)) / 2h."""
    estimates = []
    for step in RELATIVE_STEPS:
        h = step * scale
        estimates.append((loss_at(h) - loss_at(-h)) / (2 * h))
        if relative_error(analytic, estimates[-1]) < 1e-4:
            return
    raise AssertionError(f"{name}: autodiff {analytic!r} vs central differences {estimates}")


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(MATERIALS))
def test_material_parameter_gradients_match_finite_differences(name):
    scene, material = impact_scene(), MATERIALS[name]
    sim = tm.Simulator(scene, material, checkpoint_every=25)
    _, weights = weighted_loss(sim.forward(FRAMES))
    grads = sim.backward(weights)
    assert set(grads.material) == set(material.parameters())
    for parameter, value in material.parameters().items():
        assert_matches_central_difference(
            grads.material[parameter],
            lambda h, p=parameter, v=value: loss_of(scene, material.replace(**{p: v + h})),
            max(abs(value), 1e-2),
            f"{name}.{parameter}",
        )


def test_initial_velocity_gradient_matches_finite_differences():
    scene, material = impact_scene(), MATERIALS["stvk_hencky"]
    sim = tm.Simulator(scene, material, checkpoint_every=25)
    _, weights = weighted_loss(sim.forward(FRAMES))
    grads = sim.backward(weights)
    rng = np.random.default_rng(1)
    for _ in range(3):
        direction = rng.standard_normal(scene.velocities.shape)
        assert_matches_central_difference(
            float((grads.velocities * direction).sum()),
            lambda h, d=direction: loss_of(
                scene.with_velocities(scene.velocities + h * d), material
            ),
            1.0,
            "initial velocity",
        )


@pytest.mark.heavy  # compiles the parallel variant of every kernel: minutes
def test_parallel_loops_give_the_serial_results():
    """The parallel forward kernel and parallel reverse kernels agree with the serial ones."""
    scene, material = impact_scene(), MATERIALS["von_mises"]
    results = []
    for parallel in (False, True):
        sim = tm.Simulator(scene, material, checkpoint_every=25, parallel=parallel)
        positions = sim.forward(FRAMES)
        grads = sim.backward(weighted_loss(positions)[1])
        results.append((positions, grads))
    (pos_serial, grads_serial), (pos_parallel, grads_parallel) = results
    # Only the order of atomic additions differs: agreement to float64 round-off.
    np.testing.assert_allclose(pos_parallel, pos_serial, rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        grads_parallel.velocities, grads_serial.velocities, rtol=1e-9, atol=1e-12
    )
    for name, value in grads_serial.material.items():
        assert relative_error(grads_parallel.material[name], value) < 1e-9, name


def test_backward_twice_gives_the_same_gradients():
    """backward re-runs whatever segment is not recorded, also on a second call."""
    sim = tm.Simulator(impact_scene(), MATERIALS["von_mises"], checkpoint_every=25)
    weights = weighted_loss(sim.forward(FRAMES))[1]
    first, second = sim.backward(weights), sim.backward(weights)
    assert first.material == second.material
    np.testing.assert_array_equal(first.velocities, second.velocities)


def test_angular_velocity_gradient_by_chain_rule():
    """rigid_velocity_gradient turns dL/dv0 into dL/d(angular velocity) of a rigid spin."""
    base = impact_scene()
    linear, angular = np.array([0.8, -3.0, 0.3]), np.array([2.0, -1.0, 3.0])

    def scene_with(omega):
        return base.with_velocities(tm.rigid_velocity(base.positions, linear, omega))

    material = MATERIALS["neo_hookean"]
    sim = tm.Simulator(scene_with(angular), material, checkpoint_every=25)
    weights = weighted_loss(sim.forward(FRAMES))[1]
    _, d_angular = tm.rigid_velocity_gradient(base.positions, sim.backward(weights).velocities)
    for axis in range(3):
        unit = np.eye(3)[axis]
        assert_matches_central_difference(
            d_angular[axis],
            lambda h, u=unit: loss_of(scene_with(angular + h * u), material),
            1.0,
            f"angular velocity[{axis}]",
        )
