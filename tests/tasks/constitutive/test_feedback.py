"""The trajectory table of the feedback keeps the rows that say something: the largest errors
(at most TRAJECTORY_ROWS, in particle and time order, each with its error), one line for the
rest, and a single line when every row agrees to the printed millimetre. Synthetic
trajectories only: nothing is simulated."""

from __future__ import annotations

import re

import numpy as np
import pytest

from tasks.constitutive import feedback
from tasks.constitutive.feedback import CORNERS, TRAJECTORY_FRAMES, TRAJECTORY_ROWS
from tasks.constitutive.inner import InnerResult, InnerSettings

STEPS, DT = 200, 1e-3
ROWS = CORNERS * TRAJECTORY_FRAMES
ROW = re.compile(r"^  t = (\d+\.\d+) s: simulated \(.*\), observed \(.*\), error (\d+\.\d) mm$")


def observed_motion(particles: int = 64, seed: int = 0) -> np.ndarray:
    """(STEPS + 1, particles, 3): a falling, slowly shearing block."""
    rng = np.random.default_rng(seed)
    start = rng.uniform(0.4, 0.6, size=(particles, 3))
    t = np.arange(STEPS + 1)[:, None, None] * DT
    shear = np.array([1.0, 0.0, 0.0]) * (start[None, :, 1:2] - 0.5) * 5 * t
    return start[None] + np.array([0.0, -4.9, 0.0]) * t**2 + shear


def table(predicted: np.ndarray, observed: np.ndarray, particles: int = CORNERS) -> str:
    corners = feedback.corner_particles(observed[0], particles)
    return feedback.trajectory_text(predicted, observed, DT, corners)


def test_a_law_that_fits_gets_one_line():
    observed = observed_motion()
    noise = np.random.default_rng(1).normal(0, 1e-4, observed.shape)
    text = table(observed + noise, observed)
    corners = feedback.corner_particles(observed[0])
    frames = np.linspace(0, STEPS, TRAJECTORY_FRAMES + 1).round().astype(int)[1:]
    largest = np.linalg.norm(noise[np.ix_(frames, corners)], axis=-1).max()
    assert text.splitlines() == [text]
    assert text.startswith("Trajectories of corner particles (x, y, z in m; y points up)")
    assert f"all {ROWS} positions agree to within the printed precision (1.0 mm)" in text
    assert text.endswith(f"largest error {largest * 1e3:.1f} mm.")


def test_a_bad_law_keeps_its_worst_rows_in_order():
    observed = observed_motion()
    drift = np.linspace(0, 1, STEPS + 1)[:, None, None] * np.array([0.0, 0.02, 0.0])
    predicted = observed + drift * (1 + np.arange(observed.shape[1]))[None, :, None] / 64
    corners = feedback.corner_particles(observed[0])
    frames = np.linspace(0, STEPS, TRAJECTORY_FRAMES + 1).round().astype(int)[1:]
    errors = np.linalg.norm((predicted - observed)[np.ix_(frames, corners)], axis=-1).T
    text = table(predicted, observed)
    lines = text.splitlines()
    assert lines[0].startswith("Trajectories of corner particles")
    assert f"the {TRAJECTORY_ROWS} of {ROWS} rows" in lines[0]
    listed = [(particle, line) for particle, line in _rows(lines)]
    assert len(listed) == TRAJECTORY_ROWS
    worst = sorted(np.argsort(-errors, axis=None)[:TRAJECTORY_ROWS])  # particle, then time
    for (particle, line), k in zip(listed, worst, strict=True):
        number, moment = divmod(int(k), TRAJECTORY_FRAMES)
        match = ROW.match(line)
        assert match and particle == number, line
        assert float(match[1]) == pytest.approx(frames[moment] * DT)
        assert match[2] == f"{errors[number, moment] * 1e3:.1f}"
    rest = np.delete(errors.reshape(-1), worst)
    assert lines[-1] == (
        f"The other {ROWS - TRAJECTORY_ROWS} rows agree to within {rest.max() * 1e3:.1f} mm "
        "(their largest error)."
    )


def test_only_the_rows_off_by_a_millimetre_are_listed():
    observed = observed_motion()
    predicted = observed.copy()
    corners = feedback.corner_particles(observed[0])
    frames = np.linspace(0, STEPS, TRAJECTORY_FRAMES + 1).round().astype(int)[1:]
    predicted[frames[-1], corners[2], 1] += 0.005  # 5 mm at the last moment
    predicted[frames[3], corners[0], 0] += 0.002
    predicted[frames[5], corners[1], 2] += 0.0004  # below the printed precision
    lines = table(predicted, observed).splitlines()
    rows = list(_rows(lines))
    assert [particle for particle, _ in rows] == [0, 2]
    assert [line.rsplit("error ", 1)[1] for _, line in rows] == ["2.0 mm", "5.0 mm"]
    assert lines[-1] == f"The other {ROWS - 2} rows agree to within 0.4 mm (their largest error)."


@pytest.mark.parametrize("seed", range(5))
def test_the_table_is_bounded(seed):
    """Whatever the errors, at most a title, a line per particle, the rows and a summary."""
    observed = observed_motion(seed=seed)
    noise = np.random.default_rng(seed).normal(0, 0.05, observed.shape)
    text = table(observed + noise, observed, particles=8)
    assert len(text.splitlines()) <= 1 + 8 + TRAJECTORY_ROWS + 1
    assert len(list(_rows(text.splitlines()))) == TRAJECTORY_ROWS


def test_a_non_finite_position_is_listed():
    observed = observed_motion()
    predicted = observed.copy()
    corner = feedback.corner_particles(observed[0])[3]
    predicted[STEPS, corner] = np.nan
    lines = table(predicted, observed).splitlines()
    assert lines[-2].endswith("error a non-finite distance")
    assert lines[-1] == f"The other {ROWS - 1} rows agree to within 0.0 mm (their largest error)."


def test_more_non_finite_positions_than_rows_are_told():
    observed = observed_motion()
    predicted = observed.copy()
    predicted[-60:] = np.nan  # the last three moments of every particle
    lines = table(predicted, observed).splitlines()
    assert len(list(_rows(lines))) == TRAJECTORY_ROWS
    assert lines[-1] == f"The other {ROWS - TRAJECTORY_ROWS} rows hold non-finite positions too."


def test_the_table_is_much_shorter_than_all_rows():
    """A fitting law's table was 40 rows (~3,500 characters); it is now one line."""
    observed = observed_motion()
    assert len(table(observed, observed)) < 300


def _rows(lines: list[str]):
    """(particle number, row line) of the listed rows."""
    particle = -1
    for line in lines:
        header = re.match(r"^Particle (\d+) \(starts at", line)
        if header:
            particle = int(header[1])
        elif line.startswith("  t = "):
            yield particle, line


def listed(line: str) -> list[int]:
    """The epochs a curve line of the feedback lists (``"0: 1.2, 3: 0.9, ..."``)."""
    return [int(epoch) for epoch in re.findall(r"(?:: |, )(\d+): ", line)]


def test_the_epochs_listed_include_the_best_one_and_the_last():
    epochs, best = 30, 25  # the paper's 30 epochs: 25 falls between the evenly spread ones
    losses = [1.0 / (1 + e) if e <= best else 0.5 for e in range(epochs)]
    result = InnerResult(losses=losses, parameters={"log_E": [13.0 + 0.01 * e for e in range(30)]},
                         best_epoch=best, best_loss=losses[best])  # fmt: skip
    lines = feedback.optimization_text(result, InnerSettings()).splitlines()
    loss_line = next(line for line in lines if line.startswith("Loss ("))
    parameter_line = next(line for line in lines if line.startswith("- log_E: "))
    assert f"Best loss {losses[best]:.6g} at epoch {best}." in lines
    for line in (loss_line, parameter_line):
        assert best in listed(line) and listed(line)[-1] == epochs - 1 and listed(line)[0] == 0
        assert listed(line) == sorted(set(listed(line)))
    assert f"{best}: {losses[best]:.4g}" in loss_line
    assert feedback.listed_epochs(8, 5) == list(range(8))  # few epochs: all of them


def test_one_rejected_trial_point_is_singular():
    result = InnerResult(losses=[2.0, 1.0], parameters={"a": [0.0, 1.0]}, best_epoch=1,
                         best_loss=1.0, rejected_trials=["a=nan"])  # fmt: skip
    text = feedback.optimization_text(result, InnerSettings(optimizer="lbfgs"))
    assert "1 trial point of the line search was rejected" in text
