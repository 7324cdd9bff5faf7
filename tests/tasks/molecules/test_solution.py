"""Reading proposals from solution text (nothing is executed)."""

from __future__ import annotations

import pytest

from tasks.molecules.solution import ProposalError, format_solution, parse_solution


def test_reads_annotated_assignments_in_a_fence() -> None:
    text = (
        "### Code\n```python\n# a comment\nSMILES: str = 'CCO'  # 3 atoms\n"
        "coordinates: list[list[float]] = [[0, 0, 0], [1.5, 0.0, 0.0], (2.0, 1.2, -0.5)]\n```\n"
    )
    proposal = parse_solution(text)
    assert proposal.smiles == "CCO"
    assert proposal.coordinates == [[0.0, 0.0, 0.0], [1.5, 0.0, 0.0], [2.0, 1.2, -0.5]]


def test_reads_bare_code_and_the_last_python_block() -> None:
    assert parse_solution('SMILES = "CC"\ncoordinates = [[0, 0, 0], [1.5, 0, 0]]').smiles == "CC"
    text = (
        '```python\nSMILES = "CC"\ncoordinates = [[0, 0, 0]]\n```\n'
        '```python\nSMILES = "CN"\ncoordinates = [[0, 0, 0]]\n```'
    )
    assert parse_solution(text).smiles == "CN"


def test_round_trip_with_format_solution() -> None:
    rows = [[0.0, 0.1, -0.2], [1.234, 5.678, 9.012]]
    proposal = parse_solution(format_solution("CO", rows))
    assert proposal.smiles == "CO" and proposal.coordinates == rows


def test_code_is_never_executed(tmp_path) -> None:
    marker = tmp_path / "ran"
    text = (
        f"import pathlib\npathlib.Path({str(marker)!r}).write_text('x')\n"
        'SMILES = "CCO"\ncoordinates = [[0, 0, 0], [1, 0, 0], [2, 0, 0]]\n'
    )
    assert parse_solution(text).smiles == "CCO"
    assert not marker.exists()


@pytest.mark.parametrize(
    ("text", "phrase"),
    [
        ("SMILES = 'CC'\ncoordinates = [[0, 0, 0]", "not valid Python"),
        ("coordinates = [[0, 0, 0]]", "`SMILES`"),
        ("SMILES = 'CC'", "`coordinates`"),
        ("SMILES = name\ncoordinates = [[0, 0, 0]]", "string literal"),
        ("SMILES = ''\ncoordinates = [[0, 0, 0]]", "non-empty"),
        ("SMILES = 'CC'\ncoordinates = np.array([[0, 0, 0]])", "literal list"),
        ("SMILES = 'CC'\ncoordinates = []", "non-empty list"),
        ("SMILES = 'CC'\ncoordinates = [[0, 0]]", "three numbers"),
        ("SMILES = 'CC'\ncoordinates = [[0, 0, 'a']]", "three numbers"),
        ("SMILES = 'CC'\ncoordinates = [[0, 0, True]]", "three numbers"),
    ],
)
def test_unreadable_solutions_say_why(text: str, phrase: str) -> None:
    with pytest.raises(ProposalError, match=phrase.replace("(", r"\(")):
        parse_solution(text)


@pytest.mark.parametrize(
    "literal", ['"C/C=C\\NCCC"', "'C/C=C\\NCCC'", '"C/C=C\\\\NCCC"', 'r"C/C=C\\NCCC"']
)
def test_backslash_smiles_read_as_meant(literal: str) -> None:
    """`\\N` is a broken Python escape; a SMILES literal holding it is read as a raw string."""
    text = f"SMILES: str = {literal}\ncoordinates = [[0, 0, 0]]\n"
    assert parse_solution(text).smiles == "C/C=C\\NCCC"
