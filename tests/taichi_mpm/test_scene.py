"""Scene helpers: rigid velocity, its chain rule and its least-squares inverse."""

import numpy as np

import taichi_mpm as tm


def test_rigid_velocity_fit_inverts_rigid_velocity():
    positions, _ = tm.cube((0.5, 0.4, 0.5), 0.2, 4)
    linear, angular = np.array([0.8, -2.0, 0.3]), np.array([2.0, -1.0, 3.0])
    velocities = tm.rigid_velocity(positions, linear, angular)
    fitted_linear, fitted_angular = tm.rigid_velocity_fit(positions, velocities)
    np.testing.assert_allclose(fitted_linear, linear, atol=1e-12)
    np.testing.assert_allclose(fitted_angular, angular, atol=1e-12)
