"""System identification recovers hidden material parameters from synthetic motion."""

import logging

import numpy as np
import pytest

import taichi_mpm as tm
from taichi_mpm.sysid import FitError, fit, identify, observation_from_times

pytestmark = pytest.mark.slow  # fits of a simulated observation: seconds each

FRAMES = np.arange(10, 151, 10)


def thrown_cube() -> tm.Scene:
    """A 5^3-particle cube thrown, spinning, into the floor of a 16^3 grid."""
    positions, volume = tm.cube((0.45, 0.3, 0.5), 0.2, 5)
    velocities = tm.rigid_velocity(positions, (0.8, -2.0, 0.3), (2.0, -1.0, 3.0))
    return tm.Scene(positions, velocities, volume, grid_resolution=16, dt=4e-4, steps=150)


def synthetic(material: tm.Material, noise: float = 0.0, seed: int = 0):
    scene = thrown_cube()
    positions = tm.Simulator(scene, material).forward(FRAMES)
    observation = observation_from_times(scene, positions, FRAMES * scene.dt)
    if noise:
        rng = np.random.default_rng(seed)
        noisy = positions + noise * observation.body_size * rng.standard_normal(positions.shape)
        observation = observation_from_times(scene, noisy, FRAMES * scene.dt)
    return observation


def relative_errors(found: dict, truth: dict) -> dict:
    return {name: abs(found[name] / truth[name] - 1.0) for name in found}


@pytest.mark.parametrize("optimizer", ["lbfgs", pytest.param("adam", marks=pytest.mark.heavy)])
def test_neo_hookean_E_and_nu_recovered_from_guesses_off_by_3x(optimizer):
    truth = tm.Material(tm.NeoHookean(E=5e4, nu=0.3))
    observation = synthetic(truth)
    guess = truth.replace(E=1.5e5, nu=0.15)
    settings = {"lbfgs": {"learning_rate": 0.5}, "adam": {"learning_rate": 0.1}}[optimizer]
    result = fit(
        observation,
        guess,
        optimizer=optimizer,
        iterations=150,
        tolerance=1e-7,
        patience=20,
        **settings,
    )
    errors = relative_errors(result.values, truth.parameters())
    assert max(errors.values()) < 0.02, (result.values, result.iterations)
    assert result.loss_curve[-1] < 1e-3 * result.loss_curve[0]


@pytest.mark.slow
def test_neo_hookean_recovered_under_one_percent_noise():
    truth = tm.Material(tm.NeoHookean(E=5e4, nu=0.3))
    observation = synthetic(truth, noise=0.01)
    result = fit(
        observation,
        truth.replace(E=2e4, nu=0.2),
        optimizer="lbfgs",
        learning_rate=0.5,
        iterations=100,
        tolerance=1e-7,
        patience=10,
    )
    errors = relative_errors(result.values, truth.parameters())
    assert max(errors.values()) < 0.10, result.values


HENCKY = tm.StVKHencky(E=5e4, nu=0.3)
PLASTIC_CASES = {
    # material, the parameter fitted, a guess 2x-3x off
    "von_mises_yield_stress": (tm.Material(HENCKY, tm.VonMises(2e3)), "yield_stress", 5e3),
    "sand_friction_angle": (tm.Material(HENCKY, tm.DruckerPrager(30.0)), "friction_angle", 12.0),
    # nu is known, so fitting E fits the bulk modulus K = E / (3 (1 - 2 nu))
    "fluid_bulk_modulus": (
        tm.Material(tm.StVKHencky(E=2e4, nu=0.3), tm.WeaklyCompressibleFluid()),
        "E",
        6e4,
    ),
}


@pytest.mark.parametrize("case", sorted(PLASTIC_CASES))
@pytest.mark.parametrize("noise", [0.0, pytest.param(0.01, marks=pytest.mark.heavy)])
def test_plastic_parameters_recovered(case, noise):
    truth, name, guess = PLASTIC_CASES[case]
    observation = synthetic(truth, noise=noise)
    result = fit(
        observation,
        truth.replace(**{name: guess}),
        names=[name],
        optimizer="lbfgs",
        learning_rate=0.5,
        iterations=60,
        tolerance=1e-7,
        patience=10,
    )
    error = abs(result.values[name] / truth.parameters()[name] - 1.0)
    assert error < (0.10 if noise else 0.02), (case, result.values)


def test_fit_rejects_unknown_parameters_and_optimizers():
    observation = synthetic(tm.Material(tm.NeoHookean(E=5e4, nu=0.3)))
    material = tm.Material(tm.NeoHookean(E=5e4, nu=0.3))
    with pytest.raises(FitError, match="this material has parameters"):
        fit(observation, material, names=["yield_stress"])
    with pytest.raises(FitError, match="use one of"):
        fit(observation, material, optimizer="sgd")


@pytest.mark.heavy
def test_initial_velocity_fitted_jointly_when_not_observed():
    truth = tm.Material(tm.NeoHookean(E=5e4, nu=0.3))
    observation = synthetic(truth)
    result = fit(
        observation,
        truth.replace(E=1.5e5),
        names=["E"],
        optimizer="lbfgs",
        learning_rate=0.5,
        iterations=100,
        tolerance=1e-9,
        patience=15,
        fit_velocity=True,
        initial_velocity=((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
    )
    linear, angular = result.initial_velocity[:3], result.initial_velocity[3:]
    np.testing.assert_allclose(linear, [0.8, -2.0, 0.3], atol=0.02)
    np.testing.assert_allclose(angular, [2.0, -1.0, 3.0], atol=0.05)
    assert abs(result.values["E"] / 5e4 - 1) < 0.02, result.values


@pytest.mark.slow
def test_unstable_step_backs_off_instead_of_crashing():
    """A huge first step makes E 3000x too stiff for dt: the fit halves its step and goes on."""
    truth = tm.Material(tm.NeoHookean(E=5e4, nu=0.3))
    result = fit(
        synthetic(truth),
        truth.replace(E=2e4),
        names=["E"],
        optimizer="adam",
        learning_rate=8.0,
        iterations=30,
        tolerance=1e-8,
        patience=20,
    )
    assert result.backoffs >= 1
    assert np.isfinite(result.loss) and result.loss < result.loss_curve[0]


@pytest.mark.heavy
def test_fit_from_a_subset_of_particles_and_sparse_frames():
    truth = tm.Material(tm.NeoHookean(E=5e4, nu=0.3))
    scene = thrown_cube()
    frames = np.array([50, 100, 150])  # three frames only
    subset = np.random.default_rng(3).choice(scene.num_particles, 20, replace=False)
    observed = tm.Simulator(scene, truth).forward(frames)[:, subset]
    observation = observation_from_times(scene, observed, frames * scene.dt, subset)
    result = fit(
        observation,
        truth.replace(E=1.5e5, nu=0.15),
        optimizer="lbfgs",
        learning_rate=0.5,
        iterations=100,
        tolerance=1e-9,
        patience=15,
    )
    errors = relative_errors(result.values, truth.parameters())
    assert max(errors.values()) < 0.02, result.values


def test_progress_is_logged_and_printed_only_when_verbose(capsys, caplog):
    """A library call prints nothing; its progress goes to the taichi_mpm.sysid logger, and
    to stderr with verbose=True (one line per step and per phase)."""
    truth = tm.Material(tm.NeoHookean(E=5e4, nu=0.3))
    observation = synthetic(truth)
    guess = truth.replace(E=1.5e5)
    with caplog.at_level(logging.INFO, logger="taichi_mpm.sysid"):
        fit(observation, guess, ["E"], iterations=2)
    assert capsys.readouterr() == ("", "")
    assert [r.name for r in caplog.records] == ["taichi_mpm.sysid"] * 4
    assert caplog.records[1].getMessage().startswith("iteration 1: loss ")

    fit(observation, guess, ["E"], iterations=2, verbose=True)
    out, err = capsys.readouterr()
    lines = err.splitlines()
    assert out == "" and len(lines) == 4
    assert lines[0].startswith("fitting E with adam, at most 2 iterations")
    assert lines[1].startswith("iteration 1: loss ") and lines[1].endswith(", E 1.5e+05")
    assert lines[2].startswith("iteration 2: loss ")
    assert lines[3].startswith("stopped without converging after 2 iterations: loss ")

    identify(observation, guess, ["E"], restarts=2, iterations=1, verbose=True)
    lines = capsys.readouterr().err.splitlines()
    assert [line.split(":")[0] for line in lines] == ["run 1/2"] * 3 + ["run 2/2"] * 3 + [
        "uncertainties"
    ]
    assert lines[-1] == "uncertainties: 2 simulations around the best fit"
