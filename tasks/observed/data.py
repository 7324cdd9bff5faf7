"""The observation as the ``observed`` task uses it: read once per file version and cut to the
frames fitted.

Imports NumPy and taichi_mpm's observation reader only (no torch), so options and prompts
stay cheap.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from taichi_mpm.scene import Scene
from taichi_mpm.sysid.observation import Observation, load_observation


def read_observation(path: str | Path) -> Observation:
    """The checked observation in ``path`` (:func:`taichi_mpm.sysid.load_observation`; its
    ``ObservationError`` names what is wrong), read again only when the file changes."""
    path = Path(path)
    stat = path.stat() if path.is_file() else None
    key = (stat.st_mtime_ns, stat.st_size) if stat else None
    return _read(str(path), key)


@functools.lru_cache(maxsize=4)
def _read(path: str, version: tuple[int, int] | None) -> Observation:
    return load_observation(path)


@dataclass(frozen=True)
class ObservedData:
    """The fitted part of an observation: the frames after t = 0 up to ``frames`` of them,
    the scene cut to end at the last of them."""

    observation: Observation
    scene: Scene
    frame_steps: np.ndarray  # (frames,) steps of the fitted frames, all > 0
    positions: np.ndarray  # (frames, P, 3) observed positions at them

    @classmethod
    def load(cls, path: str | Path, frames: int | None = None) -> ObservedData:
        observation = read_observation(path)
        later = observation.frame_steps > 0
        steps, positions = observation.frame_steps[later], observation.positions[later]
        if frames is not None:
            steps, positions = steps[:frames], positions[:frames]
        scene = dataclasses.replace(observation.scene, steps=int(steps[-1]))
        return cls(observation, scene, steps, positions)

    @property
    def particles(self) -> np.ndarray:
        """Indices of the observed particles in the scene."""
        return self.observation.particle_indices

    @property
    def body_size(self) -> float:
        return self.observation.body_size

    def describe(self) -> dict[str, Any]:
        """Facts about the scene and the data for the prompt (no material in them)."""
        scene = self.scene
        x, v = scene.positions, scene.velocities
        centre = x.mean(axis=0)
        r = x - centre
        momentum = np.cross(r, v - v.mean(axis=0)).sum(axis=0)
        inertia = (r**2).sum() * np.eye(3) - r.T @ r
        spin = np.linalg.lstsq(inertia, momentum, rcond=None)[0]
        return {
            "particles": scene.num_particles, "observed": len(self.particles),
            "extent": np.ptp(x, axis=0), "centre": centre, "velocity": v.mean(axis=0),
            "spin": spin, "density": scene.density, "grid": scene.grid_resolution,
            "domain": scene.domain_size, "dt": scene.dt, "steps": scene.steps,
            "gravity": np.asarray(scene.gravity), "walls": scene.walls,
            "frames": len(self.frame_steps), "times": self.frame_steps * scene.dt,
        }  # fmt: skip


def truth_path(observation: str | Path) -> Path:
    """Where ``scripts/make_observation.py`` writes the hidden truth of an observation."""
    return Path(observation).with_suffix(".truth.json")


def read_truth(observation: str | Path) -> dict[str, Any] | None:
    """The hidden truth beside ``observation`` (``family`` and ``parameters``), or None when
    there is no readable one. For reports only: never shown to a proposer."""
    try:
        truth = json.loads(truth_path(observation).read_text())
        return {"family": str(truth["family"]),
                "parameters": {str(k): float(v) for k, v in truth["parameters"].items()}}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None


def file_sha256(path: str | Path) -> str | None:
    """The sha256 of the file at ``path`` (None when it cannot be read)."""
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return None


def provenance(observation: str, validation: str | None) -> dict[str, Any]:
    """What a run is measured against: the observation file and its sha256, the hidden truth
    beside it (as :func:`read_truth` reads it), and the validation file and its sha256."""
    record: dict[str, Any] = {
        "observation": observation, "observation_sha256": file_sha256(observation),
        "truth": read_truth(observation),
    }  # fmt: skip
    if validation is not None:
        record |= {"validation": validation, "validation_sha256": file_sha256(validation)}
    return record
