"""Scene helpers: rigid velocity, its chain rule and its least-squares inverse."""

import numpy as np
import pytest

import taichi_mpm as tm


def test_rigid_velocity_fit_inverts_rigid_velocity():
    positions, _ = tm.cube((0.5, 0.4, 0.5), 0.2, 4)
    linear, angular = np.array([0.8, -2.0, 0.3]), np.array([2.0, -1.0, 3.0])
    velocities = tm.rigid_velocity(positions, linear, angular)
    fitted_linear, fitted_angular = tm.rigid_velocity_fit(positions, velocities)
    np.testing.assert_allclose(fitted_linear, linear, atol=1e-12)
    np.testing.assert_allclose(fitted_angular, angular, atol=1e-12)


def test_a_scene_file_gives_back_the_scene_it_was_written_from(tmp_path):
    scene = tm.paper_scene(steps=37).with_velocities(np.zeros((1000, 3)))
    path = tm.save_scene(tmp_path / "probe", scene)
    assert path.name == "probe.npz"
    again = tm.load_scene(path)
    assert np.array_equal(again.positions, scene.positions)
    assert np.array_equal(again.velocities, scene.velocities)
    assert (again.steps, again.dt, again.walls, again.gravity) == (37, 5e-4, scene.walls,
                                                                  scene.gravity)  # fmt: skip


def test_a_file_that_is_no_scene_is_named_with_the_fix(tmp_path):
    with pytest.raises(tm.SceneError, match="is not a scene file"):
        tm.load_scene(tmp_path / "missing.npz")
    np.savez(tmp_path / "partial.npz", initial_positions=np.zeros((1, 3)))
    with pytest.raises(tm.SceneError, match=r"lacks \[.*'steps'\]; write it with taichi_mpm"):
        tm.load_scene(tmp_path / "partial.npz")
