"""Parsimony: a fitted parameter must win its share of the loss, in the search's ranking and in
the report's, which agree."""

from __future__ import annotations

from pathlib import Path

import pytest

from sga_agent.config import PRESETS, ConfigError, SearchConfig
from sga_agent.heap import SolutionHeap, ranked_loss
from sga_agent.report.data import Candidate, Run

#: (candidate, loss, fitted parameters): a three-constant law 0.07 % below the two-constant
#: true form (as the observed neo-Hookean search found), and a one-constant law 5 % above.
LAWS = [("extra-terms", 6.2359e-7, 3), ("true-form", 6.2402e-7, 2), ("too-simple", 6.55e-7, 1)]


def heap(parsimony: float) -> SolutionHeap:
    solutions = SolutionHeap(parsimony)
    for name, loss, count in LAWS:
        parameters = {f"k{i}": 1.0 for i in range(count)}
        solutions.push(name, "code", loss, "", True, parameters)
    solutions.push("unstable", "code", float("inf"), "", False, {})
    return solutions


def test_a_parameter_must_win_its_share_of_the_loss():
    assert heap(0.0).best().candidate == "extra-terms"
    assert [e.candidate for e in heap(0.01).top(4)] == [
        "true-form", "extra-terms", "too-simple", "unstable"]  # fmt: skip
    # a parameter that wins more than its share keeps the lead
    assert heap(0.0005).best().candidate == "extra-terms"


def test_a_negative_loss_moves_towards_zero_per_parameter():
    assert ranked_loss(-1.0, 2, 0.01) == pytest.approx(-1.0 / 1.01**2)
    assert ranked_loss(2.0, 2, 0.01) == pytest.approx(2.0 * 1.01**2)
    assert ranked_loss(float("nan"), 0, 0.01) == float("inf")


def test_the_report_ranks_as_the_search_did():
    candidates = [Candidate(name, "ok", loss, parameters={f"k{i}": 1.0 for i in range(count)})
                  for name, loss, count in LAWS]  # fmt: skip
    for parsimony in (0.0, 0.01):
        run = Run(Path("."), {"loop": {"parsimony": parsimony}}, candidates)
        assert run.best.id == heap(parsimony).best().candidate
    assert Run(Path("."), {}, candidates).best.id == "extra-terms"  # a run before parsimony


def test_the_quick_preset_prefers_fewer_constants_and_the_paper_presets_do_not():
    def loop(preset: str, **settings):
        return SearchConfig.from_preset(preset, task="t", proposer="p", **settings).loop

    assert loop("quick").parsimony == PRESETS["quick"]["parsimony"] > 0
    assert loop("quick", max_seconds=900.0).parsimony == PRESETS["quick"]["parsimony"]
    assert loop("sga").parsimony == 0.0 and loop("quick", parsimony=0.0).parsimony == 0.0
    with pytest.raises(ConfigError, match="parsimony must lie in"):
        loop("sga", parsimony=1.0)
