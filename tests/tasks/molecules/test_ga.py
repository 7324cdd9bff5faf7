"""The graph GA proposer: valid, distinct, reproducible children; operators that mostly work."""

from __future__ import annotations

import random

import pytest
from rdkit import Chem

from sga_agent.parsing import check_candidate, parse_response
from sga_agent.registry import load_task
from sga_agent.task import BuiltinProposer, Parent
from tasks.molecules.constants import SUPPORTED_ELEMENTS
from tasks.molecules.examples import DRUG_LIKE
from tasks.molecules.ga import GraphGAProposer
from tasks.molecules.ga.crossover import CUTS, crossover
from tasks.molecules.ga.graph import Limits, canonical
from tasks.molecules.ga.mutations import ELEMENTS, MUTATIONS, mutate
from tasks.molecules.geometry import build_structure
from tasks.molecules.solution import parse_solution
from tasks.molecules.task import SEED_SOLUTION
from tasks.molecules.validation import check_molecule, check_proposal
from tests.tasks.molecules.helpers import solution_for

NAMES = ("paracetamol", "aspirin", "nicotine", "lidocaine", "sulfamethoxazole", "naproxen")
MOLECULES = [check_molecule(DRUG_LIKE[name]) for name in NAMES]


@pytest.fixture(scope="module")
def parents() -> list[Parent]:
    return [Parent(solution_for(DRUG_LIKE[name]), 0.1 * i) for i, name in enumerate(NAMES[:4])]


def _smiles(text: str) -> str:
    """The stereo-free canonical SMILES of an answer or solution text."""
    return canonical(check_molecule(parse_solution(text).smiles))


@pytest.mark.parametrize("temperature", [0.5, 1.0])
def test_children_are_valid_distinct_answers(parents: list[Parent], temperature: float) -> None:
    answers = GraphGAProposer(SEED_SOLUTION).propose_from(parents, temperature, n=6, seed=3)
    assert len(answers) == 6
    taken = {_smiles(p.code) for p in parents} | {_smiles(SEED_SOLUTION)}
    children = set()
    for answer in answers:
        assert answer.count("```python") == 1
        code = parse_response(answer).code
        check_candidate(code, load_task("homo"))
        checked = check_proposal(parse_solution(code))
        assert len(parse_solution(code).coordinates) == checked.n_heavy
        assert 8 <= checked.n_heavy <= 30
        children.add(_smiles(answer))
    assert len(children) == 6
    assert not children & taken


def test_coordinates_are_used_as_proposed(parents: list[Parent]) -> None:
    """The task keeps the written geometry: bonds and atom order match the SMILES."""
    for answer in GraphGAProposer(SEED_SOLUTION).propose_from(parents, 1.0, n=3, seed=5):
        structure = build_structure(check_proposal(parse_solution(parse_response(answer).code)))
        assert structure.source == "proposal"


def test_same_seed_same_answers(parents: list[Parent]) -> None:
    proposer = GraphGAProposer(SEED_SOLUTION)
    first = proposer.propose_from(parents, 1.0, n=4, seed=11)
    assert proposer.propose_from(parents, 1.0, n=4, seed=11) == first
    assert GraphGAProposer(SEED_SOLUTION).propose_from(parents, 1.0, n=4, seed=11) == first
    assert proposer.propose_from(parents, 1.0, n=4, seed=12) != first


def test_temperature_sets_boldness(parents: list[Parent]) -> None:
    proposer = GraphGAProposer(SEED_SOLUTION)
    cold = proposer.propose_from(parents, 0.5, n=8, seed=1)
    assert all(answer.splitlines()[1].count(" -> ") == 1 for answer in cold)
    assert all("crossover" not in answer for answer in cold)
    hot = proposer.propose_from(parents, 1.0, n=8, seed=1)
    assert any("crossover" in answer or answer.count(" -> ") > 1 for answer in hot)


def test_seed_molecule_fills_in() -> None:
    """Unreadable parents, and one too large to yield children, leave the seed's mutations."""
    too_large = Parent(solution_for("CCCCCCCCCC(CCCCCCCCCC)CCCCCCCCCCCCCCC"), 0.0)
    broken = Parent("SMILES = 'C1CC'\ncoordinates = [[0, 0, 0]]", 0.0)
    answers = GraphGAProposer(SEED_SOLUTION).propose_from([broken, too_large], 0.5, n=3, seed=0)
    assert len(answers) == 3
    assert all("the seed molecule ->" in answer for answer in answers)


def _rate(make: object, trials: int) -> float:
    valid = 0
    for trial in range(trials):
        child = make(random.Random(trial))
        if child is not None:
            checked = check_molecule(Chem.MolToSmiles(child))
            assert 8 <= checked.GetNumAtoms() <= 30
            valid += 1
    return valid / trials


@pytest.mark.parametrize("operator", list(MUTATIONS))
def test_mutations_mostly_succeed(operator: str) -> None:
    rate = _rate(lambda rng: mutate(rng.choice(MOLECULES), rng, Limits(), operator)[0], trials=60)
    print(f"{operator}: {rate:.0%} valid")
    assert rate >= 0.3


@pytest.mark.parametrize("kind", list(CUTS))
def test_crossovers_often_succeed(kind: str) -> None:
    rate = _rate(lambda rng: crossover(*rng.sample(MOLECULES, 2), rng, Limits(), kind)[0], 60)
    print(f"{kind}: {rate:.0%} valid")
    assert rate >= 0.2


def test_contract_and_settings() -> None:
    proposer = GraphGAProposer(SEED_SOLUTION)
    assert isinstance(proposer, BuiltinProposer)
    assert proposer.name == "builtin:ga"
    assert proposer.propose_from([], 0.5, n=0, seed=0) == []
    assert set(ELEMENTS) <= set(SUPPORTED_ELEMENTS)
    with pytest.raises(ValueError, match="max_atoms"):
        Limits(max_atoms=50)
    with pytest.raises(ValueError, match="attempts_per_child"):
        GraphGAProposer(SEED_SOLUTION, attempts_per_child=0)
