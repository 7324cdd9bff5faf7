"""Shared pieces of the ``observed`` task's tests: the task registered through a dist-info
entry point (as an installed distribution registers it), and synthetic observations."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.plugins import register_task


@pytest.fixture
def registered(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> dict[str, str]:
    """``observed`` in the ``sga_agent.tasks`` group here and in processes started with the
    returned environment (the installed metadata may predate the entry point)."""
    site = tmp_path / "site"
    env = register_task(site, "observed", "tasks.observed:ObservedTask")
    monkeypatch.syspath_prepend(str(site))
    return env


def observation_arrays(frames: int = 4, particles: int = 8, count: int = 27) -> dict:
    """The arrays of a well-formed observation file of a small scene (positions made up)."""
    rng = np.random.default_rng(0)
    initial = 0.4 + 0.1 * rng.random((count, 3))
    return {
        "positions": np.repeat(initial[None, :particles], frames, axis=0),
        "times": 1e-3 * np.arange(1, frames + 1),
        "particle_indices": np.arange(particles),
        "initial_positions": initial,
        "initial_velocities": np.zeros((count, 3)),
        "particle_volume": 1e-4, "density": 1e3, "grid_resolution": 16, "domain_size": 1.0,
        "dt": 1e-3, "gravity": np.array([0.0, -9.8, 0.0]), "walls": "slip",
        "wall_thickness": 3, "wall_friction": 0.0,
    }  # fmt: skip


def ready_task(name: str, folder: Path):
    """The registered task ``name``, set up on a small observation written into ``folder``
    where its seed and prompt need options (``observed``, plastic searched)."""
    from sga_agent.registry import load_task
    from tasks.observed.options import ObservedOptions

    task = load_task(name)
    if name != "observed":
        return task
    path = folder / "observed.npz"
    np.savez(path, **observation_arrays())
    return task.with_options(ObservedOptions(str(path), "plastic", E=5e4, nu=0.3))
