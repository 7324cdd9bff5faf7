"""Scenes: particle samplers, initial velocity, walls, and the paper's preset."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

WALL_KINDS = ("slip", "sticky", "separate")


class SceneError(ValueError):
    """A scene is malformed; the message names the field and the fix."""


@dataclass(frozen=True)
class Walls:
    """Box walls on all six faces of the domain.

    ``kind`` is ``"slip"`` (the normal velocity into the wall is removed), ``"sticky"``
    (all velocity is removed) or ``"separate"`` (as slip, with Coulomb ``friction`` on
    the tangential velocity). ``thickness`` is the wall depth in grid cells.
    """

    kind: str = "slip"
    thickness: int = 3
    friction: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in WALL_KINDS:
            raise SceneError(f"Walls.kind={self.kind!r} is unknown; use one of {WALL_KINDS}")
        if self.thickness < 1:
            raise SceneError(f"Walls.thickness={self.thickness} must be >= 1 cell")
        if not (math.isfinite(self.friction) and self.friction >= 0):
            raise SceneError(f"Walls.friction={self.friction} must be >= 0")
        if self.friction > 0 and self.kind != "separate":
            raise SceneError(
                f"Walls.friction={self.friction} only acts on 'separate' walls; "
                f"use Walls('separate', friction=...) or friction=0 with kind={self.kind!r}"
            )


@dataclass(frozen=True)
class Scene:
    """Initial particles and the numerical set-up of one simulation.

    Parameters
    ----------
    positions : (N, 3) array
        Initial particle positions, inside the cube [0, domain_size]^3.
    velocities : (N, 3) array
        Initial particle velocities.
    particle_volume : float
        Initial volume of one particle (m^3).
    density : float
        Mass density (kg/m^3); particle mass = density * particle_volume.
    grid_resolution : int
        Cells per side n of the n^3 grid; dx = domain_size / n.
    dt : float
        Time step (s).
    steps : int
        Number of steps.
    gravity : 3-tuple
        Acceleration (m/s^2).
    walls : Walls
        Boundary condition on the six faces.
    """

    positions: np.ndarray
    velocities: np.ndarray
    particle_volume: float
    density: float = 1e3
    grid_resolution: int = 20
    domain_size: float = 1.0
    dt: float = 5e-4
    steps: int = 1000
    gravity: tuple[float, float, float] = (0.0, -9.8, 0.0)
    walls: Walls = field(default_factory=Walls)

    def __post_init__(self) -> None:
        x = np.ascontiguousarray(self.positions, dtype=np.float64)
        v = np.ascontiguousarray(self.velocities, dtype=np.float64)
        object.__setattr__(self, "positions", x)
        object.__setattr__(self, "velocities", v)
        if x.ndim != 2 or x.shape[1] != 3 or x.shape[0] == 0:
            raise SceneError(f"positions must have shape (N, 3) with N >= 1, got {x.shape}")
        if v.shape != x.shape:
            raise SceneError(
                f"velocities must have the shape of positions {x.shape}, got {v.shape}"
            )
        if not (np.isfinite(x).all() and np.isfinite(v).all()):
            raise SceneError("positions and velocities must be finite (found NaN or inf)")
        if self.grid_resolution < 4:
            raise SceneError(f"grid_resolution={self.grid_resolution} must be >= 4")
        for name in ("particle_volume", "density", "domain_size", "dt"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise SceneError(f"{name}={value} must be a positive number")
        if self.steps < 1:
            raise SceneError(f"steps={self.steps} must be >= 1")
        low, high = self.dx, self.domain_size - 2 * self.dx
        if x.min() < low or x.max() > high:
            raise SceneError(
                f"particles must lie in [{low:g}, {high:g}] (one cell inside the domain) so "
                f"their stencil fits the grid; found coordinates in [{x.min():g}, {x.max():g}]. "
                "Move the body or enlarge domain_size."
            )
        if 2 * self.walls.thickness >= self.grid_resolution:
            raise SceneError(
                f"walls {self.walls.thickness} cells thick leave no room in a "
                f"{self.grid_resolution}^3 grid; use thinner walls or a finer grid"
            )

    @property
    def num_particles(self) -> int:
        return self.positions.shape[0]

    @property
    def dx(self) -> float:
        return self.domain_size / self.grid_resolution

    @property
    def particle_mass(self) -> float:
        return self.density * self.particle_volume

    def with_velocities(self, velocities: np.ndarray) -> Scene:
        """A copy with other initial velocities."""
        return _replace(self, velocities=velocities)

    def with_positions(self, positions: np.ndarray) -> Scene:
        """A copy with other initial positions."""
        return _replace(self, positions=positions)


def _replace(scene: Scene, **changes) -> Scene:
    return dataclasses.replace(scene, **changes)


# -------------------------------------------------------------------------- samplers


def cube(center, side: float, particles_per_side: int) -> tuple[np.ndarray, float]:
    """Regular lattice of particles_per_side^3 points filling a cube.

    Returns the (N, 3) positions and the volume of one particle.
    """
    if particles_per_side < 1 or side <= 0:
        raise SceneError("cube needs side > 0 and particles_per_side >= 1")
    spacing = side / particles_per_side
    axis = (np.arange(particles_per_side) + 0.5) * spacing - 0.5 * side
    grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    return grid + np.asarray(center, dtype=np.float64), spacing**3


def sphere(center, radius: float, spacing: float) -> tuple[np.ndarray, float]:
    """Lattice points with the given spacing inside a ball; returns positions, volume each."""
    if radius <= 0 or spacing <= 0:
        raise SceneError("sphere needs radius > 0 and spacing > 0")
    count = int(math.ceil(2 * radius / spacing))
    axis = (np.arange(count) + 0.5) * spacing - 0.5 * count * spacing
    grid = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    inside = grid[np.linalg.norm(grid, axis=1) <= radius]
    if len(inside) == 0:
        raise SceneError("sphere: spacing is larger than the ball; use a smaller spacing")
    return inside + np.asarray(center, dtype=np.float64), spacing**3


def rigid_velocity(positions: np.ndarray, linear, angular) -> np.ndarray:
    """v = linear + angular x (x - centroid) for every particle."""
    positions = np.asarray(positions, dtype=np.float64)
    arm = positions - positions.mean(axis=0)
    return np.asarray(linear, dtype=np.float64) + np.cross(
        np.asarray(angular, dtype=np.float64), arm
    )


def rigid_velocity_gradient(positions: np.ndarray, velocity_grad: np.ndarray):
    """Chain rule of :func:`rigid_velocity`: (dL/dlinear, dL/dangular) from dL/dv."""
    arm = np.asarray(positions) - np.asarray(positions).mean(axis=0)
    return velocity_grad.sum(axis=0), np.cross(arm, velocity_grad).sum(axis=0)


def rigid_velocity_fit(positions: np.ndarray, velocities: np.ndarray):
    """Least-squares (linear, angular) with velocities ~ :func:`rigid_velocity`."""
    arm = np.asarray(positions) - np.asarray(positions).mean(axis=0)
    linear = np.asarray(velocities).mean(axis=0)
    # angular x arm = -[arm]_x angular: stack the skew matrices of every arm
    skew = np.zeros((len(arm), 3, 3))
    skew[:, 0, 1], skew[:, 0, 2] = arm[:, 2], -arm[:, 1]
    skew[:, 1, 0], skew[:, 1, 2] = -arm[:, 2], arm[:, 0]
    skew[:, 2, 0], skew[:, 2, 1] = arm[:, 1], -arm[:, 0]
    angular = np.linalg.lstsq(skew.reshape(-1, 3), (velocities - linear).ravel(), rcond=None)[0]
    return linear, angular


# --------------------------------------------------------------------------- presets

PAPER_LINEAR_VELOCITY = (1.0, -0.5, -0.75)
PAPER_ANGULAR_VELOCITY = (1.0, 3.0, 2.0)


def paper_scene(steps: int = 1000, particles_per_side: int = 10) -> Scene:
    """The constitutive-law scene of the SGA paper.

    A cube of side 0.5 centred in the unit domain, 10^3 particles, density 1e3, grid
    20^3 (dx = 0.05), dt = 5e-4, 1000 steps, gravity -9.8 along y, slip walls 3 cells
    thick, initial velocity (1.0, -0.5, -0.75) plus angular velocity (1, 3, 2).

    ``particles_per_side`` n refines it: n^3 particles on a (2n)^3 grid, so that each cell
    holds one particle as in the paper's scene (n = 10); the body, its motion, the time step
    and the walls' thickness in cells stay.
    """
    if particles_per_side < 2:
        raise SceneError(f"particles_per_side={particles_per_side} must be >= 2")
    positions, volume = cube((0.5, 0.5, 0.5), 0.5, particles_per_side)
    velocities = rigid_velocity(positions, PAPER_LINEAR_VELOCITY, PAPER_ANGULAR_VELOCITY)
    return Scene(
        positions=positions,
        velocities=velocities,
        particle_volume=volume,
        density=1e3,
        grid_resolution=2 * particles_per_side,
        domain_size=1.0,
        dt=5e-4,
        steps=steps,
        gravity=(0.0, -9.8, 0.0),
        walls=Walls(kind="slip", thickness=3),
    )
