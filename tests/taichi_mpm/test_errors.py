"""Bad input fails early with errors that name the problem and the fix."""

import numpy as np
import pytest

import taichi_mpm as tm


def cube_scene(**changes):
    positions, volume = tm.cube((0.5, 0.5, 0.5), 0.2, 3)
    values = dict(positions=positions, velocities=np.zeros_like(positions), particle_volume=volume)
    values.update(changes)
    return tm.Scene(**values)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"positions": np.zeros((4, 2))}, "shape"),
        ({"velocities": np.zeros((3, 3))}, "velocities must have the shape"),
        ({"positions": np.full((27, 3), np.nan)}, "finite"),
        ({"positions": np.full((27, 3), 0.99)}, "enlarge domain_size"),
        ({"dt": -1.0}, "dt=-1.0 must be a positive"),
        ({"steps": 0}, "steps=0"),
    ],
)
def test_malformed_scene_is_rejected(changes, message):
    with pytest.raises(tm.SceneError, match=message):
        cube_scene(**changes)


def test_wall_errors_name_the_fix():
    with pytest.raises(tm.SceneError, match="use one of"):
        tm.Walls("bouncy")
    with pytest.raises(tm.SceneError, match="only acts on 'separate' walls"):
        tm.Walls("slip", friction=0.5)


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (lambda: tm.NeoHookean(E=-1.0, nu=0.3), "E=-1.0 must be a positive"),
        (lambda: tm.NeoHookean(E=1e5, nu=0.5), r"nu=0.5 must lie in \(-1, 0.5\)"),
        (lambda: tm.VonMises(yield_stress=0.0), "yield_stress"),
        (lambda: tm.DruckerPrager(friction_angle=95.0), "friction_angle"),
        (lambda: tm.PlasticMixture([(0.5, tm.VonMises(1e3)), (0.5, tm.VonMises(2e3))]), "once"),
    ],
)
def test_bad_material_values_are_rejected(build, message):
    with pytest.raises(tm.MaterialError, match=message):
        build()


def test_unknown_parameter_names_the_known_ones():
    material = tm.Material(tm.NeoHookean(E=1e5, nu=0.3))
    with pytest.raises(tm.MaterialError, match=r"\['E', 'nu'\]"):
        material.replace(yield_stress=1.0)


def test_backward_checks_its_input():
    sim = tm.Simulator(cube_scene(steps=2), tm.Material(tm.NeoHookean(E=1e5, nu=0.3)))
    with pytest.raises(RuntimeError, match="call forward"):
        sim.backward(np.zeros((1, 27, 3)))
    sim.forward([1, 2])
    with pytest.raises(ValueError, match=r"shape of the recorded positions \(2, 27, 3\)"):
        sim.backward(np.zeros((1, 27, 3)))
    with pytest.raises(ValueError, match=r"frames must lie in \[0, 2\]"):
        sim.forward([3])
