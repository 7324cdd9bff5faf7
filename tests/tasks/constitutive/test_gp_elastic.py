"""The elastic law search: admissible laws (frame indifferent, stress-free at rest), checked
against the laws' own stress, and the pairs of forms it tries first."""

from __future__ import annotations

import importlib.util
import math
import random
import re
import sys
from pathlib import Path

import torch

from sga_agent.parsing import parse_response
from sga_agent.task import Parent
from tasks.constitutive import prompt_text
from tasks.constitutive.gp import GeneticProgrammingProposer
from tasks.constitutive.gp.admissible import (
    ISOTROPIC,
    LEFT,
    MATERIAL,
    RIGHT,
    SPATIAL,
    admissible,
    admissible_term,
    at_rest,
    frame,
)
from tasks.constitutive.gp.codegen import genome_from_code, law_code
from tasks.constitutive.gp.elastic_forms import FORMS, RESPONSES
from tasks.constitutive.gp.enumeration import elastic_pairs, loose_form
from tasks.constitutive.gp.genome import Genome, Node, Param, Term, fits, random_genome, to_json
from tasks.constitutive.gp.proposer import CONSTANT_MOVES, DESCRIPTIONS, PAIR_SPREAD
from tasks.constitutive.gp.seeds import seed_genome
from tasks.constitutive.law_code import load_law

ROOT = Path(__file__).resolve().parents[3]
b, I, F, eps = Node("b"), Node("I"), Node("F"), Node("eps")  # noqa: E741 (the identity)
NEO_HOOKEAN_SHEAR = Node("sub", (b, I))
PRESSURE = Node("spatial", (Node("vol", (eps,)),))  # log(J) I / 3


def term_value(expr: Node, deformation: torch.Tensor) -> torch.Tensor:
    """The unsymmetrised value of the one-term law ``expr`` at unit modulus."""
    code = law_code(Genome("elastic", (Term(Param("log", 0.0), expr),)))
    code = code.replace("return 0.5 * (stress + stress.transpose(-2, -1))", "return stress")
    with torch.no_grad():
        return load_law(code, torch.float64)(deformation)


def random_terms(count: int, seed: int) -> list[Node]:
    rng = random.Random(seed)
    terms: list[Node] = []
    while len(terms) < count:
        terms += [term.expr for term in random_genome(rng, "elastic").terms]
    return terms


def test_how_a_term_transforms_is_how_its_stress_transforms_under_a_rotation():
    generator = torch.Generator().manual_seed(0)
    deformation = torch.eye(3, dtype=torch.float64) + 0.2 * torch.randn(
        16, 3, 3, generator=generator, dtype=torch.float64
    )
    rotation, _ = torch.linalg.qr(torch.randn(16, 3, 3, generator=generator, dtype=torch.float64))
    rotation = rotation * torch.linalg.det(rotation).sign().view(-1, 1, 1)
    back = rotation.transpose(-2, -1)
    expected = {SPATIAL: lambda a: rotation @ a @ back, ISOTROPIC: lambda a: a,
                LEFT: lambda a: rotation @ a, RIGHT: lambda a: a @ back,
                MATERIAL: lambda a: a}  # fmt: skip
    checked = {name: 0 for name in expected}
    F_T, R = Node("T", (F,)), Node("R")
    products = [Node("matmul", pair) for pair in [(F, F_T), (F_T, F), (R, F_T), (b, F), (F_T, b),
                                                  (Node("matmul", (F_T, F)), F_T)]]  # fmt: skip
    for expr in products + random_terms(400, seed=1):
        kind = frame(expr)
        if kind is None:
            continue
        before, after = term_value(expr, deformation), term_value(expr, rotation @ deformation)
        if not (torch.isfinite(before).all() and torch.isfinite(after).all()):
            continue
        scale = max(before.abs().max().item(), 1e-3)
        assert (after - expected[kind](before)).abs().max().item() <= 1e-6 * scale, expr
        checked[kind] += 1
    assert min(checked.values()) >= 1 and checked[SPATIAL] >= 100, checked


def test_a_terms_value_at_rest_is_its_stress_at_rest():
    at_identity = torch.eye(3, dtype=torch.float64).expand(2, 3, 3)
    known = 0
    for expr in random_terms(400, seed=2):
        value = at_rest(expr)
        if value is None:
            continue
        stress = term_value(expr, at_identity)
        assert torch.allclose(stress, value * at_identity, rtol=1e-6, atol=1e-6), expr
        known += 1
    assert known >= 200


def test_textbook_terms_are_admissible_and_the_linear_seeds_are_not():
    log_J = Node("log_J")
    assert admissible_term(NEO_HOOKEAN_SHEAR) and admissible_term(Node("smul", (log_J, I)))
    assert admissible_term(Node("spatial", (eps,))) and admissible_term(Node("dev", (b,)))
    assert not admissible_term(b)  # a stress at rest
    assert not admissible_term(Node("sub", (F, I)))  # turns with F, not with the body
    assert not admissible_term(Node("smul", (Node("const", (Param("log", 0.0),)), I)))
    assert not admissible(seed_genome("elastic"))


def load_generator():
    spec = importlib.util.spec_from_file_location(
        "make_elastic_forms", ROOT / "scripts" / "make_elastic_forms.py"
    )
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(spec.name, module)
    spec.loader.exec_module(module)
    return module


def test_the_table_of_elastic_forms_is_what_its_script_writes():
    generator = load_generator()
    assert generator.render(generator.listed_forms()) == (
        ROOT / "tasks" / "constitutive" / "gp" / "elastic_forms.py"
    ).read_text(), "run: python scripts/make_elastic_forms.py"


def test_elastic_pairs_are_admissible_distinct_and_hold_neo_hookean_early():
    pairs = elastic_pairs()
    assert len(pairs) == len({loose_form(pair) for pair in pairs}) >= 40
    assert all(fits(pair) and admissible(pair) and len(pair.terms) == 2 for pair in pairs)
    pressures = {text for text, _, pressure in FORMS if pressure}
    assert pressures, "a pressure form is listed"
    split = len(FORMS) - len(pressures)  # each other form beside the one pressure form
    for pair in pairs[:split]:
        assert any(to_json(Genome("elastic", (term,))) in pressures for term in pair.terms)
    neo_hookean = next(
        i for i, pair in enumerate(pairs)
        if {t.expr for t in pair.terms} == {NEO_HOOKEAN_SHEAR, PRESSURE}
    )  # fmt: skip
    assert neo_hookean < split


def seed_parent(loss: float = 5e-5) -> Parent:
    return Parent(prompt_text.ELASTIC_SEED, loss, {"log_youngs_modulus": 10.9,
                                                   "poissons_ratio": -0.8})  # fmt: skip


def test_explore_children_try_the_pairs_in_order_at_the_fitted_stiffness():
    proposer = GeneticProgrammingProposer("elastic")
    first = proposer.propose_from([seed_parent()], 1.0, 12, seed=1)
    second = proposer.propose_from([seed_parent()], 1.0, 12, seed=2, tried=first)
    rank = re.compile(r"tried pair of forms (\d+) in order")
    ranks = [[int(m.group(1)) for a in batch if (m := rank.search(a))] for batch in (first, second)]
    assert len(ranks[0]) >= 6 and ranks[0] == list(range(1, len(ranks[0]) + 1))
    assert min(ranks[1]) == len(ranks[0]) + 1
    # the seed's stiffest fitted modulus: its shear modulus, E / 2(1 + nu), nu clamped to 0.01
    stiffness = 10.9 - math.log(2 * 1.01)
    pairs = [genome_from_code(parse_response(a).code, "elastic") for a in first if rank.search(a)]
    moduli = [term.coefficient.raw for pair in pairs for term in pair.terms]
    assert abs(sum(moduli) / len(moduli) - stiffness) < PAIR_SPREAD
    assert not any(rank.search(a) for a in proposer.propose_from([seed_parent()], 0.5, 12, 1))


def test_pairs_start_with_the_small_strain_response_of_the_best_admissible_parent():
    hencky = Genome("elastic", (Term(Param("log", 13.8), PRESSURE),
                                Term(Param("log", 12.7), Node("spatial", (Node("dev", (eps,)),)))))
    known = Parent(law_code(hencky), 1e-7, {})
    shear, volume = 0.5 * math.exp(12.7), math.exp(13.8)  # its response, from the table
    answers = GeneticProgrammingProposer("elastic").propose_from(
        [seed_parent(1e-5), known], 1.0, 16, seed=4)
    matched = 0
    for answer in answers:
        pair = genome_from_code(parse_response(answer).code, "elastic")
        if "tried pair of forms" not in answer or pair is None:
            continue
        responses = [RESPONSES[to_json(Genome("elastic", (Term(Param("log", 0.0), t.expr),)))]
                     for t in pair.terms]  # fmt: skip
        moduli = [math.exp(t.coefficient.raw) for t in pair.terms]
        got = [sum(m * r[i] for m, r in zip(moduli, responses, strict=True)) for i in (0, 1)]
        determinant = responses[0][0] * responses[1][1] - responses[1][0] * responses[0][1]
        if abs(determinant) > 1e-9 and all(m > 0 for m in moduli):
            # noise of PAIR_SPREAD on each log-modulus: within a factor e^(4 spread)
            assert abs(math.log(got[0] / shear)) < 4 * PAIR_SPREAD, (answer, got)
            assert abs(math.log(got[1] / volume)) < 4 * PAIR_SPREAD, (answer, got)
            matched += 1
    assert matched >= 4


def test_new_elastic_structure_is_admissible():
    proposer = GeneticProgrammingProposer("elastic")
    pool = [seed_parent(), Parent(law_code(Genome("elastic", (
        Term(Param("log", 11.0), NEO_HOOKEAN_SHEAR), Term(Param("log", 11.0), PRESSURE)))), 1e-5)]
    moves = [DESCRIPTIONS[name] for name in CONSTANT_MOVES]
    answers = [a for t in (0.5, 1.0) for a in proposer.propose_from(pool, t, 40, seed=5)]
    structural = [a for a in answers if not any(move in a for move in moves)]
    assert len(structural) >= 30
    for answer in structural:
        assert admissible(genome_from_code(parse_response(answer).code, "elastic")), answer
