"""A scene as a file: the initial state and set-up of one simulation, in ``.npz``.

The keys are those of an observation file (:mod:`taichi_mpm.sysid.observation`) without its
observed frames, plus ``steps``: ``initial_positions``, ``initial_velocities``,
``particle_volume``, ``density``, ``grid_resolution``, ``domain_size``, ``dt``, ``gravity``,
``walls``, ``wall_thickness``, ``wall_friction``. A probe experiment a search proposes is
written this way, to be simulated (``taichi_mpm.Simulator(load_scene(path), material)``) or
set up in a laboratory.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from taichi_mpm.scene import Scene, SceneError, Walls

#: The keys that describe a scene's initial state and set-up (an observation has them too).
SCENE_KEYS = ("initial_positions", "initial_velocities", "particle_volume", "density",
              "grid_resolution", "domain_size", "dt", "gravity", "walls", "wall_thickness",
              "wall_friction")  # fmt: skip


def scene_arrays(scene: Scene) -> dict[str, Any]:
    """The :data:`SCENE_KEYS` of ``scene``, as ``np.savez`` takes them."""
    return {
        "initial_positions": scene.positions, "initial_velocities": scene.velocities,
        "particle_volume": scene.particle_volume, "density": scene.density,
        "grid_resolution": scene.grid_resolution, "domain_size": scene.domain_size,
        "dt": scene.dt, "gravity": np.asarray(scene.gravity), "walls": scene.walls.kind,
        "wall_thickness": scene.walls.thickness, "wall_friction": scene.walls.friction,
    }  # fmt: skip


def scene_from_arrays(values: dict[str, Any], steps: int = 1) -> Scene:
    """The scene the :data:`SCENE_KEYS` of ``values`` describe (a ``SceneError`` or a
    ``ValueError`` names what is wrong)."""
    return Scene(
        positions=values["initial_positions"],
        velocities=values["initial_velocities"],
        particle_volume=float(values["particle_volume"]),
        density=float(values["density"]),
        grid_resolution=int(values["grid_resolution"]),
        domain_size=float(values["domain_size"]),
        dt=float(values["dt"]),
        steps=steps,
        gravity=tuple(float(g) for g in values["gravity"]),
        walls=Walls(
            str(values["walls"]), int(values["wall_thickness"]), float(values["wall_friction"])
        ),
    )


def save_scene(path: str | Path, scene: Scene) -> Path:
    """Write ``scene`` as ``.npz`` (the suffix added when missing); returns the path."""
    path = Path(path)
    if path.suffix != ".npz":  # numpy would add it silently
        path = path.with_name(path.name + ".npz")
    np.savez(path, steps=scene.steps, **scene_arrays(scene))
    return path


def load_scene(path: str | Path) -> Scene:
    """The scene written by :func:`save_scene` at ``path``."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            values = {key: data[key] for key in data.files}
    except (OSError, ValueError, AttributeError, TypeError) as error:
        raise SceneError(f"'{path}' is not a scene file (.npz from save_scene): {error}") from error
    missing = [key for key in (*SCENE_KEYS, "steps") if key not in values]
    if missing:
        raise SceneError(f"'{path}' lacks {missing}; write it with taichi_mpm.save_scene")
    return scene_from_arrays(values, int(values["steps"]))
