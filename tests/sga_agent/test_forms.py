"""The record of whether the data determine a solution's form (sga_agent.task.forms)."""

from __future__ import annotations

import json
import math

import pytest

from sga_agent.task import Probe, compared, within_noise

PROBES = {name: Probe(name, f"the body {name}") for name in ("an impact", "a stretch")}


def test_a_form_fits_equally_within_twice_the_best_loss_or_the_floor():
    assert within_noise([1e-6, 5e-6]) == pytest.approx(2e-6)
    assert within_noise([1e-11, 5e-6], floor=1e-9) == pytest.approx(2e-9)  # float's floor
    assert within_noise([]) == math.inf


def test_one_form_within_the_noise_is_singled_out_and_nothing_is_simulated():
    found = compared(["a", "b"], [1.0, 9.5], 2.0, {}, PROBES, 0.05)
    assert found.forms == ["a"] and found.determined and found.probe is None
    assert found.sentence == ("the observation singles out the best form: the next distinct "
                              "form's loss is 9.5x the best's")  # fmt: skip


def test_forms_that_agree_on_every_probe_determine_the_motion():
    found = compared(["a", "b", "c"], [1.0, 1.5, 3.0], 2.0,
                     {"an impact": 0.004, "a stretch": 1e-6}, PROBES, 0.05)  # fmt: skip
    assert found.forms == ["a", "b"] and found.losses == [1.0, 1.5]
    assert found.determined and found.probe is None
    assert found.sentence == (
        "the observation determines the motion: 2 distinct forms fit it within the noise "
        "(losses 1 to 1.5, at most 2) and agree on 2 probe scenes (an impact, a stretch) to "
        "within 0.4 % of the body size")


def test_forms_that_part_name_the_probe_that_separates_them_most():
    found = compared(["a", "b"], [1.0, 1.2], 2.0, {"an impact": 0.09, "a stretch": 0.06},
                     PROBES, 0.05)  # fmt: skip
    assert not found.determined and found.probe == PROBES["an impact"]
    assert found.sentence.startswith("the observation does not determine the law: 2 distinct "
                                     "forms fit it within the noise")  # fmt: skip
    assert "differ by up to 9 % of the body size under an impact; observing the body an " \
        "impact would separate them" in found.sentence  # fmt: skip


def test_an_unstable_form_is_a_disagreement_and_a_probe_where_all_are_is_left_out():
    found = compared(["a", "b"], [1.0, 1.2], 2.0, {"an impact": math.nan, "a stretch": math.inf},
                     PROBES, 0.05)  # fmt: skip
    assert found.spreads == {"a stretch": math.inf} and found.probe == PROBES["a stretch"]
    assert "one of them is unstable under a stretch" in found.sentence
    data = json.loads(json.dumps(found.to_dict()))  # JSON-ready, inf as a string
    assert data["spreads"] == {"a stretch": "inf"} and data["determined"] is False
    assert data["probe"] == {"name": "a stretch", "text": "the body a stretch", "file": ""}


def test_a_written_probe_names_its_scene_file():
    probe = Probe("an impact", "the body thrown down", "/runs/x/probes/an-impact.npz")
    found = compared(["a", "b"], [1.0, 1.0], 2.0, {"an impact": 0.5}, {"an impact": probe},
                     0.05)  # fmt: skip
    assert found.sentence.endswith("observing the body thrown down (scene file "
                                   "/runs/x/probes/an-impact.npz) would separate them")  # fmt: skip
