"""Small scenes used by several taichi_mpm tests."""

import numpy as np

import taichi_mpm as tm


def impact_scene(steps: int = 60, walls: tm.Walls | None = None, speed: float = -3.0) -> tm.Scene:
    """A 4^3-particle cube thrown, spinning, into the floor of a 16^3 grid."""
    positions, volume = tm.cube((0.45, 0.27, 0.5), 0.16, 4)
    velocities = tm.rigid_velocity(positions, (0.8, speed, 0.3), (2.0, -1.0, 3.0))
    return tm.Scene(
        positions=positions,
        velocities=velocities,
        particle_volume=volume,
        grid_resolution=16,
        dt=4e-4,
        steps=steps,
        walls=walls or tm.Walls("slip", thickness=3),
    )


def weighted_loss(positions: np.ndarray, seed: int = 0):
    """A fixed random linear functional of the trajectory and its gradient."""
    weights = np.random.default_rng(seed).standard_normal(positions.shape)
    return float((weights * positions).sum()), weights
