"""identify() reports what the observation determines, and what it cannot."""

import numpy as np
import pytest

import taichi_mpm as tm
from taichi_mpm.sysid import identify, observation_from_times
from tests.taichi_mpm.sysid.test_fit import synthetic

LBFGS = {"optimizer": "lbfgs", "learning_rate": 0.5, "tolerance": 1e-7}


@pytest.mark.heavy
def test_impact_determines_E_and_nu_and_restarts_agree():
    truth = tm.Material(tm.NeoHookean(E=5e4, nu=0.3))
    result = identify(
        synthetic(truth, noise=0.01),
        truth.replace(E=1.5e5, nu=0.15),
        restarts=2,
        iterations=60,
        **LBFGS,
    )
    assert result.identifiable, result.summary()
    assert len(result.runs) == 2
    for name, value in truth.parameters().items():
        assert abs(result.best.values[name] / value - 1) < 0.05
        assert 0 < result.relative_std[name] < 0.05  # measured 0.3% (E) and 0.7% (nu)
    assert "all parameters identified" in result.summary()


def test_free_flight_says_the_elastic_parameters_are_not_identified():
    """No contact, no spin: the body never deforms, so E and nu leave no trace."""
    truth = tm.Material(tm.NeoHookean(E=5e4, nu=0.3))
    positions, volume = tm.cube((0.5, 0.6, 0.5), 0.2, 4)
    velocities = np.tile([0.3, 0.5, 0.0], (len(positions), 1))
    scene = tm.Scene(positions, velocities, volume, grid_resolution=16, dt=4e-4, steps=60)
    frames = np.arange(10, 61, 10)
    observed = tm.Simulator(scene, truth).forward(frames)
    observation = observation_from_times(scene, observed, frames * scene.dt)
    result = identify(observation, truth.replace(E=1.5e5, nu=0.15), iterations=20, **LBFGS)
    assert not result.identifiable
    assert any("does not depend on E" in text for text in result.warnings), result.warnings
    assert any("does not depend on nu" in text for text in result.warnings), result.warnings
    assert not np.isfinite(result.relative_std["E"])


@pytest.mark.slow
def test_fluid_determines_only_its_bulk_modulus_not_E_and_nu_apart():
    """F is reset to J^(1/3) I, so only K = E / (3 (1 - 2 nu)) acts: the fit finds K and
    reports that E and nu cannot be separated."""
    truth = tm.Material(tm.StVKHencky(E=2e4, nu=0.3), tm.WeaklyCompressibleFluid())
    result = identify(
        synthetic(truth), truth.replace(E=4e4, nu=0.2), restarts=2, iterations=40, **LBFGS
    )
    fitted_k, true_k = result.material.elastic.bulk_modulus, truth.elastic.bulk_modulus
    assert abs(fitted_k / true_k - 1) < 0.02
    assert not result.identifiable
    assert any(
        "E" in text and "nu" in text and "change together" in text for text in result.warnings
    ), result.warnings
    # The two restarts land on different points of the same K: reported without curvature.
    assert any("restarts reach the same loss but disagree on E" in t for t in result.warnings)
