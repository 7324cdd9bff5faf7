"""The neighbourhood of a fitted form: variants one change away, tried in a fixed order."""

import math
import random
import re
from pathlib import Path

import pytest
import torch

from bridges.linalg import stable_linalg
from sga_agent.parsing import parse_response
from sga_agent.task import Parent
from tasks.constitutive import prompt_text
from tasks.constitutive.gp import GeneticProgrammingProposer, grammar
from tasks.constitutive.gp.canonical import form
from tasks.constitutive.gp.codegen import genome_from_code, law_code, with_values
from tasks.constitutive.gp.genome import from_json, random_genome, sites
from tasks.constitutive.gp.neighbourhood import APEX_SCALE, neighbours
from tasks.constitutive.law_code import load_law
from tests.tasks.constitutive.test_gp import (
    SAND_SLOPE,
    assert_runs,
    deformations,
    successive_batches,
)

LAWS = Path(__file__).resolve().parents[3] / "examples" / "laws"
CONE = '{"kind":"plastic","terms":[[["unit",1.0],["from_strain",["cone",["eps"],["const",["log",-0.6]]]]]]}'  # noqa: E501
ELASTIC = ('{"kind":"elastic","terms":[[["log",10.0],["spatial",["dev",["eps"]]]],'
           '[["log",11.0],["spatial",["vol",["eps"]]]]]}')  # fmt: skip


def outputs(code: str, F: torch.Tensor, **values: float) -> torch.Tensor:
    law = load_law(code, torch.float64)
    with torch.no_grad(), stable_linalg():
        for name, value in values.items():
            getattr(law, name).fill_(value)
        return law(F)


def strained(batch: int = 64) -> torch.Tensor:
    """Deformations squeezed or stretched by a few percent, so that some are compressed
    beyond a cone's apex and some are not."""
    F = deformations(batch, spread=0.05, seed=3)
    scale = torch.linspace(0.93, 1.03, batch, dtype=torch.float64).view(-1, 1, 1)
    return F * scale


def test_the_cone_with_a_shifted_apex_is_drucker_prager_with_cohesion():
    """The first neighbour of the Drucker-Prager form, its apex at the cohesion c and the cone's
    slope at the textbook one, is ``drucker_prager_cohesion.py`` to float precision; with its
    apex at 0, where it starts, it is the parent."""
    genome = from_json(CONE)
    shifted, change = next(neighbours(genome))
    assert change == "shifted the apex of its cone"
    code = law_code(shifted)
    F = strained()
    parent = outputs(law_code(genome), F)
    assert torch.allclose(outputs(code, F), parent, atol=1e-12)
    cohesion, angle = 0.02, 25.0  # the granular task's sand: E = 1e6 Pa, nu = 0.2
    scale = 2 * math.exp(APEX_SCALE)  # the apex is scale * tanh(u)
    ours = outputs(code, F, log_k1=math.log(SAND_SLOPE), log_k2=math.log(scale),
                   atanh_k3=math.atanh(cohesion / scale))  # fmt: skip
    truth = outputs((LAWS / "drucker_prager_cohesion.py").read_text(), F,
                    log_friction_angle=math.log(angle), cohesion=cohesion)  # fmt: skip
    assert not torch.allclose(truth, parent, atol=1e-4)  # the cohesion matters here
    assert torch.allclose(ours, truth, atol=1e-10)


@pytest.mark.parametrize("text", [CONE, ELASTIC])
def test_neighbours_are_new_valid_forms_that_start_near_their_parent(text):
    """Every neighbour is a form other than its parent's, none twice, each a law that runs
    with finite gradients (elastic ones admissible: symmetric stress, none at rest); each
    starts within a few percent of its parent's output, most of them exactly there."""
    genome = from_json(text)
    found = list(neighbours(genome))
    keys = [form(child) for child, _ in found]
    assert form(genome) not in keys and len(set(keys)) == len(keys) >= 10
    F = strained(16)
    parent = outputs(law_code(genome), F)
    for child, change in found:
        assert_runs(law_code(child), genome.kind)
        if change.startswith(("shifted", "made", "added")):
            start = outputs(law_code(child), F)
            assert torch.allclose(start, parent, rtol=0.05, atol=0.05 * parent.abs().max()), change


def test_random_generation_never_writes_a_shifted_apex():
    """``shifted_cone`` belongs to the neighbourhood: random laws and swaps never draw it."""
    rng = random.Random(0)
    for kind in ("elastic", "plastic"):
        for _ in range(200):
            genome = random_genome(rng, kind)
            ops = {s.expr.op for t in genome.terms for s in sites(t.expr) if hasattr(s.expr, "op")}
            assert "shifted_cone" not in ops
        assert "shifted_cone" not in grammar.alternatives("P", "cone", kind)


def test_the_exploit_batch_tries_the_neighbours_of_the_best_form_in_order():
    """After the continuation, an exploit batch's next child is the first untried neighbour of
    the best distinct parent, from its fitted values; the next batch the one after it; an
    explore batch none."""
    genome = from_json(CONE)
    best = Parent(law_code(genome), 1e-6, {"weight0": 1.0, "log_k1": -0.6})
    pool = [best, Parent(prompt_text.PLASTIC_SEED, 1e-3)]
    proposer = GeneticProgrammingProposer("plastic")
    batches = successive_batches(proposer, pool, 0.5, 2, 3)
    tried = [answer for batch in batches for answer in batch]
    ranks = []
    for answers in batches:
        near = [a for a in answers if "tried neighbour" in a]
        assert len(near) == 1
        ranks.append(int(re.search(r"tried neighbour (\d+) of the form of loss 1e-06", near[0])[1]))
    assert ranks == [1, 2, 3]
    assert "tried neighbour 1" in tried[0]  # the best parent's fit had settled: no continuation
    first = genome_from_code(parse_response(tried[0]).code, "plastic")
    assert first == with_values(next(neighbours(genome))[0], {"weight0": 1.0, "log_k1": -0.6})
    assert not any("neighbour" in a for a in proposer.propose_from(pool, 1.0, 4, seed=0))
