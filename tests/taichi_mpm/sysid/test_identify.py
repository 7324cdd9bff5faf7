"""identify() reports what the observation determines, and what it cannot."""

import numpy as np

import taichi_mpm as tm
from taichi_mpm.sysid import identify, observation_from_times
from tests.taichi_mpm.sysid.test_fit import synthetic

LBFGS = {"optimizer": "lbfgs", "learning_rate": 0.5, "tolerance": 1e-7}


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


def test_weights_of_laws_that_act_alike_are_reported_inseparable():
    """Below yield a von Mises law returns F unchanged, exactly like no plasticity: the
    observation fixes only the sum of the two mixture weights, not each of them."""
    truth = tm.Material(
        tm.NeoHookean(E=5e4, nu=0.3),
        tm.PlasticMixture([(0.5, tm.NoPlasticity()), (0.5, tm.VonMises(yield_stress=1e9))]),
    )
    result = identify(
        synthetic(truth),
        truth.replace(weight_identity=0.3, weight_von_mises=0.6),
        names=["weight_identity", "weight_von_mises"],
        iterations=40,
        **LBFGS,
    )
    weights = result.best.values
    assert abs(weights["weight_identity"] + weights["weight_von_mises"] - 1.0) < 0.02
    assert not result.identifiable
    assert any(
        "weight_identity" in text and "weight_von_mises" in text and "change together" in text
        for text in result.warnings
    ), result.warnings
