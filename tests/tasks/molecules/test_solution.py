"""Reading proposals from solution text (nothing is executed)."""

from __future__ import annotations

import pytest

from sga_agent.parsing import check_candidate
from sga_agent.registry import load_task
from sga_agent.task import CodeRejected
from tasks.molecules.solution import ProposalError, format_solution, parse_solution

TASK = load_task("homo")


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
        ("coordinates = [[0, 0, 0]]", "must assign SMILES"),
        ("SMILES = 'CC'", "must assign coordinates"),
        ("SMILES = name\ncoordinates = [[0, 0, 0]]", "'SMILES' must be a literal"),
        ("SMILES = ''\ncoordinates = [[0, 0, 0]]", "non-empty"),
        ("SMILES = 'CC'\ncoordinates = np.array([[0, 0, 0]])", "'coordinates' must be a literal"),
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


# --- the task's check: literal data only, checked before anything else --------------------


def test_molecule_with_backslash_smiles_passes() -> None:
    check_candidate('SMILES = "C/C=C\\N"\ncoordinates = [[0, 0, 0], [1.2, -0.5, 1e-3]]\n', TASK)


@pytest.mark.parametrize(
    ("code", "expected"),
    [
        (
            'import os\nSMILES = "CCO"\ncoordinates = [[0, 0, 0]]',
            "line 1: importing 'os' is not allowed: solutions may not reach files, processes or "
            "the network; this task's code may not import anything",
        ),
        (
            'SMILES = "CCO"\ncoordinates = [[0, 0, 0]]\nprint(SMILES)',
            "line 3: only assignments of literal values",
        ),
        (
            'SMILES = "CC" + "O"\ncoordinates = [[0, 0, 0]]',
            "line 1: the value of 'SMILES' must be a literal",
        ),
        (
            'SMILES = "CCO"\ncoordinates = [[0.0, 0.0, 0.0] for _ in range(3)]',
            "line 2: the value of 'coordinates' must be a literal",
        ),
        ('SMILES = "CCO"', "the code must assign coordinates"),
        ("SMILES = 3\ncoordinates = [[0, 0, 0]]", "line 1: SMILES must be a string literal"),
        (
            'SMILES = "CCO"\ncoordinates = [[0, True, "a"]]',
            "line 2: coordinates must be a non-empty list of rows of numbers",
        ),
        (
            'SMILES: __import__("os") = "CCO"\ncoordinates = [[0, 0, 0]]',
            "'__import__' is not allowed",
        ),
        (
            'def f():\n    pass\nSMILES = "C"\ncoordinates = [[0, 0, 0]]',
            "line 1: only assignments of literal values",
        ),
    ],
    ids=[
        "import",
        "call",
        "arithmetic",
        "comprehension",
        "missing",
        "smiles-type",
        "coordinate-type",
        "annotation",
        "function",
    ],
)
def test_molecule_code_is_literal_data_only(code: str, expected: str) -> None:
    with pytest.raises(CodeRejected) as caught:
        check_candidate(code, TASK)
    assert expected in str(caught.value)


def test_the_check_and_the_reader_agree() -> None:
    """What the check lets through, the evaluation reads; what the reader refuses, the check
    refuses with the same sentence."""
    good = format_solution("CO", [[0.0, 0.1, -0.2], [1.2, 0.0, 0.0]])
    TASK.check_solution(good)
    assert parse_solution(good).smiles == "CO"
    bad = "SMILES = 'CC'\ncoordinates = [[0, 0]]\n"
    with pytest.raises(CodeRejected) as caught:
        TASK.check_solution(bad)
    with pytest.raises(ProposalError) as refused:
        parse_solution(bad)
    assert caught.value.problems == [(2, str(refused.value))]
