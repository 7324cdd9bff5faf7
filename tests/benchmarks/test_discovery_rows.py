"""The discovery benchmark's rows: each true law is a valid answer of its task, started where the
row says, with an observed row's known elastic law written in."""

import re

import pytest
import torch

from sga_agent.parsing import check_candidate
from sga_agent.registry import load_task
from tasks.constitutive.law_code import load_law
from tests.benchmarks.scripts import load_benchmark

discovery = load_benchmark("discovery")


@pytest.mark.parametrize("name", list(discovery.ROWS))
def test_every_row_s_true_law_is_an_answer_started_at_the_row_s_values(name):
    row = discovery.ROWS[name]
    code = discovery.truth_code(row)
    check_candidate(code, load_task(row.task))
    law = load_law(code, torch.float64)
    for argument, value in row.start.items():
        assert getattr(law, argument).item() == pytest.approx(value)
    if row.elastic is not None and "E, NU" in code:
        E, nu = row.elastic
        assert re.search(rf"E, NU = {E!r}, {nu!r}", code)


def test_the_cohesive_row_observes_a_sand_with_cohesion_and_starts_at_twice_its_constants():
    row = discovery.ROWS["observed-cohesive"]
    assert row.observation[:2] == ("--material", "sand") and "cohesion=0.02" in row.observation
    assert row.start["cohesion"] == pytest.approx(2 * 0.02)
