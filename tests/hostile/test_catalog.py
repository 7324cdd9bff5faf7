"""Sanity of the hostile corpus: enough candidates, every category, valid files and headers.

Nothing here runs a candidate: files are compiled (``compile`` executes nothing) and parsed.
"""

from __future__ import annotations

import ast
from collections import Counter

import pytest

from sga_agent.parsing import check_candidate
from sga_agent.registry import load_task
from sga_agent.task import CodeRejected
from tests.hostile.catalog import (
    CANDIDATES,
    CATEGORIES,
    EXPECTED,
    CatalogError,
    load_catalog,
    parse_candidate,
)

CATALOG = load_catalog()


def test_the_corpus_is_large_enough():
    assert len(CATALOG) >= 34


def test_every_category_and_expectation_appears():
    categories = Counter(candidate.category for candidate in CATALOG)
    assert set(categories) == set(CATEGORIES), f"missing: {set(CATEGORIES) - set(categories)}"
    assert {candidate.expected for candidate in CATALOG} == set(EXPECTED)
    assert any(candidate.task == "elastic" for candidate in CATALOG)


def test_every_file_is_in_the_catalog_with_a_unique_number():
    assert len(CATALOG) == len(list(CANDIDATES.glob("*.py")))
    numbers = [candidate.name[:2] for candidate in CATALOG]
    assert len(set(numbers)) == len(numbers), "two candidates share a number"


@pytest.mark.parametrize("candidate", CATALOG, ids=lambda candidate: candidate.name)
def test_candidate_compiles_and_defines_physics(candidate):
    compile(candidate.code, str(candidate.path), "exec")
    tree = ast.parse(candidate.code)
    classes = [node for node in tree.body if isinstance(node, ast.ClassDef)]
    assert any(node.name == "Physics" for node in classes), "no top-level class Physics"


@pytest.mark.parametrize("candidate", CATALOG, ids=lambda candidate: candidate.name)
def test_candidate_headers_parse(candidate):
    assert candidate.expected in EXPECTED
    assert candidate.category in CATEGORIES
    assert "Attack:" in candidate.description, "the docstring describes no attack"
    assert "Target:" in candidate.description, "the docstring names no target"
    assert candidate.summary.endswith("."), "the first line is a sentence"
    assert all(check and "\n" not in check for check in candidate.checks)


@pytest.mark.parametrize("candidate", CATALOG, ids=lambda candidate: candidate.name)
def test_static_header_matches_the_static_check(candidate):
    """``static: passes`` candidates reach the sandbox even through the static check."""
    try:
        check_candidate(candidate.code, load_task(candidate.task))
        verdict = "passes"
    except CodeRejected:
        verdict = "rejected"
    assert verdict == candidate.static


def test_malformed_headers_are_reported(tmp_path):
    good = (
        '"""Title.\n\nAttack: a.\nTarget: b.\n\n'
        'expected: honest\ncategory: forge\nstatic: passes\n"""\n'
    )
    path = tmp_path / "01_ok.py"
    path.write_text(good)
    assert parse_candidate(path).expected == "honest"
    for broken, message in [
        (good.replace("expected: honest\n", ""), "missing header 'expected'"),
        (good.replace("honest", "maybe"), "expected must be one of"),
        (good.replace("forge", "other"), "category must be one of"),
        (good.replace("static: passes\n", "static: passes\nstatic: passes\n"), "given twice"),
        (good + "(", "not valid Python"),
        ("x = 1\n", "no module docstring"),
    ]:
        path.write_text(broken)
        with pytest.raises(CatalogError, match=message):
            parse_candidate(path)
    misnamed = tmp_path / "hostile.py"
    misnamed.write_text(good)
    with pytest.raises(CatalogError, match="NN_short_name"):
        parse_candidate(misnamed)


def test_continuation_lines_join_their_check(tmp_path):
    text = (
        '"""T.\n\nAttack: a.\nTarget: b.\n\nexpected: refused\ncategory: names\n'
        'static: passes\ncheck: first half\n  second half\ncheck: another\n"""\n'
    )
    path = tmp_path / "02_checks.py"
    path.write_text(text)
    candidate = parse_candidate(path)
    assert candidate.checks == ("first half second half", "another")
    assert candidate.task == "granular"
