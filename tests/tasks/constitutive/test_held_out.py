"""The held-out scene of the constitutive tasks: its ground truth cached and deterministic,
the true law's free run there close to it and the seed's far off (physics: only the right law
generalizes to another body thrown otherwise), and the verdict that reads it."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from tasks.constitutive.free_run import FreeRun
from tasks.constitutive.held_out import (
    held_out_error,
    held_out_scene,
    held_out_steps,
    held_out_truth,
    true_law,
)
from tasks.constitutive.options import ConstitutiveOptions
from tasks.constitutive.specs import SPECS
from tasks.constitutive.verdict import THRESHOLDS, Thresholds, verdict

ROOT = Path(__file__).resolve().parents[3]
#: A training scene of 200 steps: a held-out one of 120 (the ball hits the floor at about 50).
SHORT = ConstitutiveOptions(steps=200)


def test_the_held_out_scene_differs_from_the_training_scene():
    import taichi_mpm as tm

    training, held_out = tm.paper_scene(), held_out_scene()
    assert held_out.num_particles != training.num_particles
    assert held_out.steps == 600 != training.steps
    spread = np.linalg.norm(held_out.positions - held_out.positions.mean(0), axis=1)
    assert spread.max() <= 0.2 + 1e-12  # a ball, not a cube
    assert not np.allclose(held_out.velocities.mean(0), training.velocities.mean(0))
    assert held_out_steps(SPECS["elastic"], SHORT) == 120
    assert held_out_steps(SPECS["elastic"], ConstitutiveOptions()) == 600


def test_the_held_out_ground_truth_is_cached_and_deterministic(tmp_path, monkeypatch):
    monkeypatch.setenv("SGA_CACHE_DIR", str(tmp_path))
    spec, options = SPECS["elastic"], ConstitutiveOptions(steps=50)
    first = held_out_truth(spec, options)
    files = list((tmp_path / "ground_truth").glob("elastic-held-out-*.npz"))
    assert len(files) == 1 and first.positions.shape == (31, 280, 3)
    assert held_out_truth(spec, options) is first  # read once, kept while the file is unchanged
    files[0].unlink()
    again = held_out_truth(spec, options)  # generated again, from scratch
    assert again is not first
    np.testing.assert_array_equal(again.positions, first.positions)
    # the ball moved: it is a simulation, not the initial state repeated
    assert np.abs(first.positions[-1] - first.positions[0]).max() > 0.02


def test_the_true_law_generalizes_and_the_seed_does_not():
    """The true neo-Hookean law (ours, and examples/laws/neo_hookean.py captured as a search
    captures a proposal) follows the held-out ground truth to float64 noise; the linear seed
    ends 5 % of the body size off or more."""
    from tasks.constitutive.law_capture import capture_law

    spec = SPECS["elastic"]
    ours = held_out_error(spec, true_law(spec), {}, SHORT)
    example = capture_law((ROOT / "examples/laws/neo_hookean.py").read_text())
    captured = held_out_error(spec, example, {"log_youngs_modulus": 13.0}, SHORT)
    seed = held_out_error(spec, capture_law(spec.seed), {}, SHORT)
    assert ours.scene == captured.scene == "held-out scene"
    assert ours.steps == 120 and ours.body_size == pytest.approx(0.35)
    assert ours.final_error < 1e-6 and captured.final_error < 1e-6
    assert seed.final_error > 0.05 and seed.final_error > 1e4 * captured.final_error
    assert ours.positions.shape == ours.observed.shape == (31, 280, 3)


def test_a_law_that_blows_up_has_an_infinite_held_out_error():
    from tasks.constitutive.law_capture import capture_law

    spec = SPECS["elastic"]
    example = capture_law((ROOT / "examples/laws/neo_hookean.py").read_text())
    run = held_out_error(spec, example, {"log_youngs_modulus": 40.0}, SHORT)
    assert run.unstable and math.isinf(run.final_error)
    assert verdict(run, None).endswith("is unstable; try a longer --time-budget or a model")


def _run(final: float, scene: str) -> FreeRun:
    return FreeRun(final, final / 2, 0.35, 600, scene=scene)


def test_the_verdict_switches_on_the_threshold_in_every_scene():
    limit = THRESHOLDS.reproduces
    below, above = _run(0.004, "held-out scene"), _run(0.51, "held-out scene")
    assert verdict(below, _run(0.02, "training scene")) == (
        "the best law reproduces the motion: 0.4 % free-run error on the held-out scene, 2 % "
        "on the training scene (5 % at most on each)"
    )
    assert verdict(above, _run(0.001, "training scene")) == (
        "the best law does not reproduce the motion: 51 % free-run error on the held-out "
        "scene, 0.1 % on the training scene (5 % at most on each); try a longer --time-budget "
        "or a model"
    )
    assert verdict(below, _run(0.09, "training scene")).startswith("the best law does not")
    assert verdict(_run(limit, "held-out scene"), None) == (
        "the best law reproduces the motion: 5 % free-run error on the held-out scene "
        "(5 % at most)"
    )
    assert "does not" in verdict(_run(limit * 1.01, "held-out scene"), None)
    assert "0.4 % free-run error on the training scene (" in verdict(None, below)
    assert "does not" in verdict(below, None, Thresholds(reproduces=0.001))
    assert verdict(None, None) == ""


@pytest.mark.slow
@pytest.mark.parametrize("name", ["plasticine", "granular", "fluid", "imaginary"])
def test_the_true_return_mapping_generalizes_and_no_plasticity_does_not(name):
    """The plastic tasks likewise: the true return mapping (bridges.laws.from_material) beside
    the known elastic law follows the ball through its impact; no plasticity (the seed) does
    not."""
    from tasks.constitutive.law_capture import capture_law

    spec = SPECS[name]
    truth = held_out_error(spec, true_law(spec), {}, SHORT)
    seed = held_out_error(spec, capture_law(spec.seed), {}, SHORT)
    assert truth.final_error < 1e-5
    assert seed.final_error > 0.02 and seed.final_error > 1e3 * truth.final_error
