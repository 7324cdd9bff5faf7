"""Fitted constants written into a law's code: the law then starts where its fit ended."""

from __future__ import annotations

from pathlib import Path

import pytest

from sga_agent.task import Parent
from tasks.constitutive.fitted_code import with_fitted_values
from tasks.constitutive.gp import GeneticProgrammingProposer
from tasks.constitutive.law_capture import capture_law
from tasks.constitutive.task import GranularTask

LAWS = Path(__file__).resolve().parents[3] / "examples" / "laws"


def parameter_values(code: str) -> dict[str, float]:
    return {p["name"]: p["values"][0] for p in capture_law(code)["parameters"]}


def gp_law() -> str:
    text = GeneticProgrammingProposer("plastic").propose_from(
        [Parent(GranularTask().seed_solution(), 1.0, {})], 1.0, 1, 3
    )[0]
    return text.split("```python\n", 1)[1].split("```", 1)[0]


@pytest.mark.slow
@pytest.mark.parametrize(
    "code", [(LAWS / "neo_hookean.py").read_text(), gp_law()], ids=["neo_hookean", "gp"]
)
def test_the_rewritten_law_starts_from_the_fitted_values(code):
    proposed = parameter_values(code)
    fitted = {name: value * 1.37 + 0.011 for name, value in proposed.items()}
    shown = with_fitted_values(code, fitted)
    assert parameter_values(shown) == pytest.approx(fitted, rel=1e-7)
    assert shown.count("\n") == code.count("\n")  # only the numbers changed


def test_literal_starts_keyword_only_defaults_and_unknown_names():
    code = '''import torch
import torch.nn as nn


class Physics(nn.Module):
    def __init__(self, *, k: float = 2.0):
        super().__init__()
        self.k = nn.Parameter(torch.tensor(float(k)))
        self.c = nn.Parameter(torch.tensor(0.5, dtype=torch.float64))

    def forward(self, F):
        return F * self.k * self.c
'''
    shown = with_fitted_values(code, {"k": 3.0, "c": -1e-9, "absent": 4.0})
    assert "k: float = 3.0" in shown and "torch.tensor(-1e-09, dtype" in shown
    assert parameter_values(shown) == {"k": 3.0, "c": -1e-9}
    assert with_fitted_values("not python (", {"k": 1.0}) == "not python ("


def test_negative_starting_values_are_rewritten_too():
    """A log of a small constant starts below zero; ``-0.63`` is a minus applied to 0.63 in the
    syntax tree, and was left as proposed (the README's law showed its start, not its fit)."""
    code = '''import torch
import torch.nn as nn


class Physics(nn.Module):
    def __init__(self, log_k: float = -0.6285, w: float = +1.0):
        super().__init__()
        self.log_k = nn.Parameter(torch.tensor(log_k))
        self.w = nn.Parameter(torch.tensor(w))
        self.c = nn.Parameter(torch.tensor(-2.5))

    def forward(self, F):
        return F * self.w * torch.exp(self.log_k + self.c)
'''
    shown = with_fitted_values(code, {"log_k": -0.6241908, "w": 0.9, "c": 3.0})
    assert "log_k: float = -0.6241908, w: float = 0.9" in shown
    assert "torch.tensor(3.0)" in shown
    assert parameter_values(shown) == pytest.approx({"log_k": -0.6241908, "w": 0.9, "c": 3.0})


@pytest.mark.slow
def test_the_task_drops_the_stale_genome_tag_of_a_gp_law():
    code = gp_law()
    fitted = {name: value + 1.0 for name, value in parameter_values(code).items()}
    shown = GranularTask().solution_with_parameters(code, fitted)
    assert "# genome:" in code and "# genome:" not in shown
    assert "\n\n\n\n" not in shown  # nor the blank line that set it off
    assert parameter_values(shown) == pytest.approx(fitted, rel=1e-7)
