"""Observed motion for system identification, and its file format.

An observation file is a NumPy ``.npz`` archive with

========================  ==================  =============================================
key                       shape / type        meaning
========================  ==================  =============================================
``positions``             (frames, P, 3)      observed particle positions (m)
``times``                 (frames,)           time of each frame (s), multiples of ``dt``
``particle_indices``      (P,) int, optional  which scene particles are observed (default
                                              all, in order)
``initial_positions``     (N, 3)              the scene: every particle at t = 0
``initial_velocities``    (N, 3)              initial velocity (a guess if it is fitted)
``particle_volume``       scalar              volume of one particle (m^3)
``density``               scalar              mass density (kg/m^3)
``grid_resolution``       scalar int          cells per side of the grid
``domain_size``           scalar              side of the cubic domain (m)
``dt``                    scalar              time step (s)
``gravity``               (3,)                acceleration (m/s^2)
``walls``                 str                 ``slip``, ``sticky`` or ``separate``
``wall_thickness``        scalar int          wall depth in cells
``wall_friction``         scalar              Coulomb friction of ``separate`` walls
========================  ==================  =============================================

:func:`save_observation` writes it and :func:`load_observation` reads and checks it.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from taichi_mpm.scene import Scene
from taichi_mpm.scene_file import SCENE_KEYS, scene_arrays, scene_from_arrays

#: Fewest frames (besides t = 0) that make a fit meaningful.
MIN_FRAMES = 2


class ObservationError(ValueError):
    """An observation is malformed; the message names the field and the fix."""


@dataclass(frozen=True)
class Observation:
    """Observed positions of some particles of a scene at some frames."""

    scene: Scene
    positions: np.ndarray  # (frames, P, 3)
    frame_steps: np.ndarray  # (frames,) step index of each frame
    particle_indices: np.ndarray  # (P,)

    def __post_init__(self) -> None:
        positions = np.asarray(self.positions, dtype=np.float64)
        steps = np.asarray(self.frame_steps, dtype=np.int64)
        raw_indices = np.asarray(self.particle_indices)
        indices = raw_indices.astype(np.int64)
        if raw_indices.size and not np.array_equal(indices, raw_indices):
            raise ObservationError("particle_indices must be whole numbers")
        object.__setattr__(self, "positions", positions)
        object.__setattr__(self, "frame_steps", steps)
        object.__setattr__(self, "particle_indices", indices)
        if positions.ndim != 3 or positions.shape[2] != 3 or positions.shape[1] == 0:
            raise ObservationError(
                "positions must have shape (frames, particles, 3) with at least one "
                f"particle, got {positions.shape}"
            )
        if not np.isfinite(positions).all():
            raise ObservationError(
                "positions contain NaN or inf; drop those frames or particles before fitting"
            )
        if steps.shape != (positions.shape[0],):
            raise ObservationError(
                f"there are {positions.shape[0]} frames of positions but {steps.shape} times"
            )
        if (steps > 0).sum() < MIN_FRAMES:
            raise ObservationError(
                f"need at least {MIN_FRAMES} frames after t = 0 to fit a material, "
                f"got {(steps > 0).sum()}"
            )
        if np.any(np.diff(steps) <= 0) or steps.min() < 0:
            raise ObservationError("frame times must be >= 0 and strictly increasing")
        if indices.shape != (positions.shape[1],):
            raise ObservationError(
                f"particle_indices has shape {indices.shape}, expected ({positions.shape[1]},)"
            )
        if indices.min() < 0 or indices.max() >= self.scene.num_particles:
            raise ObservationError(
                f"particle_indices must lie in [0, {self.scene.num_particles}) (scene particles)"
            )

    @property
    def times(self) -> np.ndarray:
        return self.frame_steps * self.scene.dt

    @property
    def body_size(self) -> float:
        """Largest extent of the initial body, the length scale of position errors."""
        x = self.scene.positions
        return float((x.max(axis=0) - x.min(axis=0)).max())


def observation_from_times(
    scene: Scene, positions: np.ndarray, times: np.ndarray, particle_indices=None
) -> Observation:
    """An :class:`Observation` whose frames are given as times (multiples of scene.dt)."""
    times = np.asarray(times, dtype=np.float64)
    steps = np.rint(times / scene.dt).astype(np.int64)
    if np.abs(steps * scene.dt - times).max(initial=0.0) > 1e-6 * scene.dt + 1e-12:
        raise ObservationError(
            f"frame times must be multiples of dt={scene.dt:g}; resample the observation"
        )
    if particle_indices is None:
        particle_indices = np.arange(np.asarray(positions).shape[1])
    steps_needed = int(steps.max()) if len(steps) else 0
    if steps_needed != scene.steps:
        scene = dataclasses.replace(scene, steps=max(steps_needed, 1))
    return Observation(scene, positions, steps, particle_indices)


def save_observation(path, observation: Observation) -> Path:
    """Write an observation as ``.npz`` (see the module docstring for the keys)."""
    scene = observation.scene
    path = Path(path)
    if path.suffix != ".npz":  # numpy would add it silently
        path = path.with_name(path.name + ".npz")
    np.savez(
        path,
        positions=observation.positions,
        times=observation.times,
        particle_indices=observation.particle_indices,
        **scene_arrays(scene),
    )
    return path


REQUIRED_KEYS = ("positions", "times", *SCENE_KEYS)


def load_observation(path) -> Observation:
    """Read and check an observation file written by :func:`save_observation`."""
    path = Path(path)
    if not path.is_file():
        raise ObservationError(f"no observation file at '{path}'")
    try:
        data = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as error:
        raise ObservationError(f"'{path}' is not a NumPy .npz archive: {error}") from error
    if not isinstance(data, np.lib.npyio.NpzFile):
        raise ObservationError(f"'{path}' holds a single array, not an .npz observation archive")
    with data:
        missing = [key for key in REQUIRED_KEYS if key not in data.files]
        if missing:
            raise ObservationError(
                f"'{path}' lacks {missing}; write it with taichi_mpm.sysid.save_observation"
            )
        values = {key: data[key] for key in data.files}
    try:
        scene = scene_from_arrays(values)
    except (TypeError, ValueError) as error:  # SceneError is a ValueError
        raise ObservationError(f"'{path}' describes an invalid scene: {error}") from error
    return observation_from_times(
        scene, values["positions"], values["times"], values.get("particle_indices")
    )
