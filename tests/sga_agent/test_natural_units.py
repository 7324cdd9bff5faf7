"""Fitted parameters in natural units: a ``log_X`` parameter stands for X = exp(value), with the
unit the task names for it, in ``sga-agent evaluate``'s table (the end screen's line is tested
with the final screen, in test_progress)."""

from __future__ import annotations

import math
from pathlib import Path

from sga_agent.cli.evaluate import _show
from sga_agent.natural_units import natural_name, natural_values, natural_values_of
from sga_agent.task import Evaluation, TaskBase
from tasks.constitutive.task import GranularTask

ROOT = Path(__file__).resolve().parents[2]
SAND = (ROOT / "examples" / "laws" / "drucker_prager.py").read_text(encoding="utf-8")


def test_a_log_parameter_stands_for_its_exp_and_others_for_nothing():
    assert natural_name("log_E") == "E" and natural_name("log_modulus0") == "modulus0"
    assert natural_name("nu") is None and natural_name("log_") is None
    values = natural_values(
        {"log_friction_angle": math.log(25.0), "nu": 0.2, "log_huge": 1e4, "log_nan": math.nan},
        {"friction_angle": "deg"},
    )
    assert list(values) == ["log_friction_angle"]  # no exp to show for the others
    assert math.isclose(values["log_friction_angle"].value, 25.0)
    assert str(values["log_friction_angle"]) == "friction angle 25 deg"
    assert str(natural_values({"log_weight_sand": math.log(0.3)})["log_weight_sand"]) == (
        "weight sand 0.3"  # no unit known: none shown
    )


class BrokenUnits(TaskBase):
    name, description, kind = "broken", "a task whose units hook fails", "equation"

    def parameter_units(self, solution, names):
        raise RuntimeError("no units today")


def test_a_failing_units_hook_costs_only_the_units():
    values = natural_values_of(BrokenUnits(), "code", {"log_E": math.log(1e6)})
    assert str(values["log_E"]) == "E 1e+06"
    assert natural_values_of(None, "", {"log_E": 0.0})["log_E"].unit == ""


def test_evaluate_shows_the_friction_angle_in_degrees_as_the_law_uses_it(capsys):
    evaluation = Evaluation(True, 1e-6, "fits", parameters={"log_friction_angle": 3.2188758})
    _show(evaluation, GranularTask(), SAND)
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if "log_friction_angle" in line)
    assert "3.21888" in row and "friction angle 25 deg" in row
    assert "stands for" in out


def test_evaluate_shows_no_natural_column_without_a_log_parameter(capsys):
    _show(Evaluation(True, 0.25, "fits", parameters={"scale": 2.0}), GranularTask(), "")
    assert "stands for" not in capsys.readouterr().out
