"""Invalid proposals give an invalid evaluation with a clear reason, and never crash."""

from __future__ import annotations

import math

import pytest

from sga_agent.task import EvaluationSettings
from tasks.molecules import HomoTask
from tasks.molecules.geometry import build_structure
from tasks.molecules.solution import Proposal, format_solution
from tasks.molecules.validation import check_proposal
from tests.tasks.molecules.helpers import conformer, score, solution_for

SMILES = "CC(=O)Nc1ccc(O)cc1"  # 11 heavy atoms


def _coords(n: int) -> list[list[float]]:
    return [[1.4 * i, 0.3 * (i % 2), 0.0] for i in range(n)]


INVALID = [
    (format_solution("CC(=O", _coords(4)), "could not be parsed"),
    (format_solution("c1cccc1CCCC", _coords(9)), "not a valid molecule"),
    (format_solution("CC(C)(C)(C)(C)CCCC", _coords(10)), "not a valid molecule"),
    (format_solution("CCCCCCCC.CCCCCCCC", _coords(16)), "fragments"),
    (format_solution("C[CH]CCCCCCC", _coords(9)), "radical"),
    (format_solution("CCCCCC", _coords(6)), "at least 8"),
    (format_solution("C" * 60, _coords(60)), "at most"),
    (format_solution("CCCCCCCC[Fe]", _coords(9)), "not supported"),
    (format_solution("CCCCCCCC[N+](C)(C)C", _coords(12)), "net charge"),
    (format_solution("[2H]CCCCCCCCC", _coords(10)), "explicit hydrogen"),
    (format_solution(SMILES, _coords(10)), "10 rows but the SMILES has 11 heavy atoms"),
    (format_solution(SMILES, _coords(12)), "12 rows"),
    (format_solution(SMILES, [[0.0, 0.0, 0.0]] * 2 + _coords(11)[2:]), "overlap"),
    ("SMILES = 'CCCCCCCC'\ncoordinates = [[float('nan'), 0, 0]] * 8", "must be a literal"),
    ("no code here at all", "not valid Python"),
    ("x = 1", "must assign"),
]


@pytest.mark.parametrize(("solution", "phrase"), INVALID)
def test_invalid_proposal_reason(solution: str, phrase: str) -> None:
    evaluation = score(HomoTask(), solution, EvaluationSettings(epochs=1))
    assert not evaluation.valid and evaluation.status == "invalid"
    assert math.isinf(evaluation.loss)
    assert "\n" not in evaluation.reason and evaluation.reason
    assert phrase in evaluation.reason
    assert evaluation.feedback == evaluation.reason


def test_non_finite_coordinates_are_rejected() -> None:
    rows = [f"[{1.4 * i}, 0.0, 0.0]" for i in range(11)]
    rows[3] = "[1e999, 0.0, 0.0]"  # a literal that overflows to inf
    text = f'SMILES = "{SMILES}"\ncoordinates = [{", ".join(rows)}]\n'
    evaluation = score(HomoTask(), text, EvaluationSettings())
    assert not evaluation.valid and "row 3 is not finite" in evaluation.reason


@pytest.mark.parametrize("garbage", ["", "```python\n```", "\x00\x01", "SMILES = 'C' * 9"])
def test_garbage_never_raises(garbage: str) -> None:
    evaluation = score(HomoTask(), garbage, EvaluationSettings(epochs=0))
    assert not evaluation.valid and evaluation.reason


def test_proposal_coordinates_are_used_when_sensible() -> None:
    heavy = conformer(SMILES)[2]
    structure = build_structure(check_proposal(Proposal(SMILES, heavy.tolist())))
    assert structure.source == "proposal" and structure.note == ""
    assert structure.rmsd < 0.2
    assert len(structure.numbers) == 20 and structure.n_heavy == 11


@pytest.mark.parametrize(
    ("smiles", "source", "scale", "phrase"),
    [
        (SMILES, SMILES, 2.5, "RMSD"),  # coordinates in the wrong unit
        ("C[C@H](N)C(=O)NCCc1ccccc1", "C[C@@H](N)C(=O)NCCc1ccccc1", 1.0, "stereochemistry"),
        ("C/C=C\\C(=O)OCCCC", "C/C=C/C(=O)OCCCC", 1.0, "stereochemistry"),
    ],
)
def test_unusable_coordinates_fall_back_to_etkdg(smiles, source, scale, phrase) -> None:
    heavy = scale * conformer(source)[2]
    structure = build_structure(check_proposal(Proposal(smiles, heavy.tolist())))
    assert structure.source == "ETKDG"
    assert phrase in structure.note and "ETKDG" in structure.note
    solution = format_solution(smiles, heavy.tolist())
    evaluation = score(HomoTask(), solution, EvaluationSettings(epochs=0))
    assert evaluation.valid
    assert evaluation.extras["geometry_source"] == "ETKDG"
    assert "not usable" in evaluation.feedback


def test_matching_stereo_keeps_the_proposal() -> None:
    for smiles in ("C[C@@H](N)C(=O)NCCc1ccccc1", "C/C=C\\C(=O)OCCCC"):
        structure = build_structure(check_proposal(Proposal(smiles, conformer(smiles)[2].tolist())))
        assert structure.source == "proposal", smiles


def test_uff_is_used_where_mmff_lacks_parameters() -> None:
    smiles = "C[Se]c1ccc(C)cc1C"
    structure = build_structure(check_proposal(Proposal(smiles, conformer(smiles)[2].tolist())))
    assert structure.force_field == "UFF"
    assert solution_for(smiles)


def test_xtb_failure_is_reported_as_unstable(monkeypatch) -> None:
    """An SCF that cannot converge (one iteration allowed) is a clear, non-crashing failure."""
    from tasks.molecules import xtb

    original = xtb.calculator_options
    monkeypatch.setattr(xtb, "calculator_options", lambda **kw: original(**{**kw, "maxiter": 1}))
    evaluation = score(HomoTask(), solution_for(SMILES), EvaluationSettings(epochs=1))
    assert not evaluation.valid and evaluation.status == "unstable"
    assert "GFN1-xTB could not be run" in evaluation.reason and "converge" in evaluation.reason
