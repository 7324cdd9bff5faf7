"""The observed task's trajectory table keeps the rows that say something, as the constitutive
tasks' does: one line when the simulation reproduces the observed frames, the worst rows with
their errors when it does not. Synthetic observation, nothing is simulated."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from tasks.constitutive.feedback import TRAJECTORY_ROWS
from tasks.observed.data import ObservedData
from tasks.observed.evaluation import trajectory_text
from tests.tasks.observed.conftest import observation_arrays

FRAMES, PARTICLES = 6, 8


def observed(tmp_path: Path) -> tuple[ObservedData, np.ndarray]:
    """The observation and simulated positions at its frames and particles (frames, P, 3), as
    a fit against its :class:`~bridges.rollout.Frames` records them, that reproduce it."""
    arrays = observation_arrays(frames=FRAMES, particles=PARTICLES)
    arrays["positions"] = arrays["positions"] + 0.01 * np.arange(FRAMES)[:, None, None]
    np.savez(tmp_path / "observed.npz", **arrays)
    data = ObservedData.load(tmp_path / "observed.npz")
    return data, data.positions.copy()


def test_a_reproduced_observation_gets_one_line(tmp_path):
    data, predicted = observed(tmp_path)
    text = trajectory_text(predicted, data)
    assert text.startswith("Trajectories of observed particles near the body's corners")
    assert text.splitlines() == [text]
    assert "agree to within the printed precision (1.0 mm); largest error 0.0 mm." in text


def test_a_poor_fit_lists_its_worst_rows(tmp_path):
    data, predicted = observed(tmp_path)
    predicted[-1] += 0.003  # every particle 5.2 mm off at the last frame
    lines = trajectory_text(predicted, data).splitlines()
    rows = [line for line in lines if line.startswith("  t = ")]
    assert rows and len(rows) <= TRAJECTORY_ROWS
    assert all(row.endswith("error 5.2 mm") for row in rows)
    assert all(f"t = {data.frame_steps[-1] * data.scene.dt:.3f} s" in row for row in rows)
    shown, total = map(int, re.search(r"the (\d+) of (\d+) rows", lines[0]).groups())
    assert shown == len(rows) and total == 4 * FRAMES  # four corners at every frame
    rest = f"The other {total - len(rows)} rows agree to within 0.0 mm (their largest error)."
    assert lines[-1] == rest
