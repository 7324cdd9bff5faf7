"""The constitutive tasks' screen (``EvaluationSettings.fidelity`` < 1): fewer epochs on the
first teacher-forced segments, counted (not timed)."""

from pathlib import Path

import numpy as np
import pytest

from sga_agent.registry import load_task
from sga_agent.task import EvaluationSettings
from tasks.constitutive.fidelity import first_segments, screen_epochs, segments
from tasks.constitutive.ground_truth import Trajectory
from tasks.constitutive.options import ConstitutiveOptions

LAWS = Path(__file__).resolve().parents[3] / "examples" / "laws"


def trajectory(steps: int, reset_every: int) -> Trajectory:
    resets = np.arange(0, steps, reset_every)
    return Trajectory(
        positions=np.arange(steps + 1, dtype=float)[:, None, None] * np.ones((1, 4, 3)),
        reset_steps=resets,
        states={"x": resets[:, None, None] * np.ones((1, 4, 3)), "F": np.ones((len(resets), 4))},
    )


@pytest.mark.parametrize(("epochs", "fidelity", "expected"),
                         [(5, 0.2, 1), (30, 0.2, 6), (5, 0.5, 3), (5, 0.01, 1), (0, 0.2, 0),
                          (7, 1.0, 7)])  # fmt: skip
def test_the_screen_runs_that_share_of_the_epochs_at_least_one(epochs, fidelity, expected):
    assert screen_epochs(epochs, fidelity) == expected


def test_the_screen_keeps_the_first_segments_of_every_array():
    whole = trajectory(1000, 100)
    cut = first_segments(whole, 100, 0.2)
    assert segments(whole, 100) == 10 and segments(cut, 100) == 2
    assert cut.positions.shape == (201, 4, 3)
    assert list(cut.reset_steps) == [0, 100]
    assert {name: len(value) for name, value in cut.states.items()} == {"x": 2, "F": 2}
    np.testing.assert_array_equal(cut.positions, whole.positions[:201])
    assert segments(first_segments(whole, 100, 0.01), 100) == 1  # at least one
    assert first_segments(whole, 100, 1.0) is whole
    assert segments(first_segments(trajectory(250, 100), 100, 0.5), 100) == 2  # 3 cut to 2


@pytest.mark.slow
def test_a_screened_law_is_fitted_on_fewer_segments_and_epochs():
    task = load_task("granular")
    data = task.capture((LAWS / "drucker_prager.py").read_text())  # a fitted friction angle
    options = ConstitutiveOptions(steps=300, optimizer="adam")  # 3 segments of 100 steps
    full = task.evaluate(data, EvaluationSettings(epochs=3, options=options))
    screen = task.evaluate(data, EvaluationSettings(epochs=3, options=options, fidelity=0.3))
    assert full.valid and screen.valid, (full.reason, screen.reason)
    assert (full.extras["segments"], full.extras["epochs"], len(full.curves["loss"])) == (3, 3, 4)
    assert (screen.extras["segments"], screen.extras["epochs"]) == (1, 1)
    assert len(screen.curves["loss"]) == 2  # one step of Adam, and the score after it
    assert screen.extras["fidelity"] == 0.3 and full.extras["fidelity"] == 1.0
