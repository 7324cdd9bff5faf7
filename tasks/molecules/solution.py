"""Reading a proposal (SMILES and heavy-atom coordinates) from solution text, without running it.

A solution is a small python block::

    SMILES: str = "CC(=O)Nc1ccc(O)cc1"  # 11 heavy atoms
    coordinates: list[list[float]] = [[x, y, z], ...]  # (11, 3), Angstrom, SMILES atom order

given bare or inside a fenced code block (the last python block wins). The text is parsed with
:mod:`ast` and only literal values are read (``ast.literal_eval``): nothing is executed.

:func:`check_solution` is the task's static check, run by the search before anything else: the
code holds only assignments of literals (an import is judged by the search's generic rules),
among them a non-empty ``SMILES`` string and ``coordinates`` rows of three numbers.
:func:`parse_solution` reads the proposal with the same rules but passes over other statements.
"""

from __future__ import annotations

import ast
import json
import re
from dataclasses import dataclass

from sga_agent.task.code import CodeRejected, Problem, parse_python

_FENCE = re.compile(r"```[ \t]*([A-Za-z0-9_+-]*)[^\n]*\n(.*?)(?:```|\Z)", re.S)
SMILES, COORDINATES = "SMILES", "coordinates"
_EXAMPLE = 'e.g. SMILES = "CCO" and coordinates = [[0.0, 0.0, 0.0], ...]'
_NOT_LITERAL = object()
_ANNOTATION_NODES = (ast.Name, ast.Attribute, ast.Subscript, ast.Tuple, ast.Constant, ast.BinOp,
                     ast.BitOr, ast.Load)  # fmt: skip


class ProposalError(ValueError):
    """The solution text does not define a usable proposal; the message is one-line feedback."""


@dataclass(frozen=True)
class Proposal:
    """A proposed molecule: SMILES and heavy-atom coordinates (Angstrom), as written."""

    smiles: str
    coordinates: list[list[float]]


def extract_code(text: str) -> str:
    """The last ```python (or untagged) fenced block of ``text``; ``text`` itself if none."""
    blocks = [(tag.lower(), body) for tag, body in _FENCE.findall(text)]
    for tag, body in reversed(blocks):
        if tag in ("python", "py", "python3", ""):
            return body
    return text


def check_solution(code: str) -> None:
    """The molecule tasks' ``check_solution``: raise :class:`~sga_agent.parsing.CodeRejected`
    listing every problem (by line) unless ``code`` holds only literal assignments, among them
    a usable ``SMILES`` and ``coordinates``."""
    _, problems = _read(parse_python(code), strict=True)
    if problems:
        raise CodeRejected(problems)


def parse_solution(text: str) -> Proposal:
    """Read ``SMILES`` and ``coordinates`` from solution text (other statements are ignored).

    Raises
    ------
    ProposalError
        The code does not parse, a name is missing, or a value is not a literal of the right
        shape (a non-empty string; a non-empty list of ``[x, y, z]`` number rows).
    """
    try:
        tree = parse_python(extract_code(text))
    except CodeRejected as error:
        raise ProposalError(str(error)) from None
    proposal, problems = _read(tree, strict=False)
    if proposal is None:
        raise ProposalError(problems[0][1])
    return proposal


def _read(tree: ast.Module, strict: bool) -> tuple[Proposal | None, list[Problem]]:
    """The proposal the top-level assignments make (the last one of a name wins), or None, and
    the problems found; ``strict`` also reports any statement but a literal assignment."""
    problems: list[Problem] = []
    values: dict[str, tuple[int, object]] = {}
    for node in tree.body:
        assignment = _assignment(node)
        if assignment is None:
            if strict and not _inert(node):
                text = "only assignments of literal values to plain names are allowed"
                problems.append((node.lineno, f"{text} ({_EXAMPLE}); nothing else is run"))
            continue
        names, value = assignment
        if strict and isinstance(node, ast.AnnAssign) and not _plain_annotation(node.annotation):
            text = "a type annotation may only name types, such as list[list[float]]"
            problems.append((node.lineno, text))
        try:
            literal = ast.literal_eval(value)
        except (ValueError, TypeError, SyntaxError, MemoryError, RecursionError):
            literal = _NOT_LITERAL
            if strict or {SMILES, COORDINATES} & set(names):
                text = f"the value of {names[0]!r} must be a literal (numbers, strings, lists)"
                text += ", without function calls, names or arithmetic"
                problems.append((node.lineno, text))
        values.update({name: (node.lineno, literal) for name in names})
    missing = [name for name in (SMILES, COORDINATES) if name not in values]
    if missing:
        problems.append((0, f"the code must assign {' and '.join(missing)} ({_EXAMPLE})"))
    smiles = _smiles(*values.get(SMILES, (0, _NOT_LITERAL)), problems)
    rows = _rows(*values.get(COORDINATES, (0, _NOT_LITERAL)), problems)
    if problems or smiles is None or rows is None:
        return None, problems
    return Proposal(smiles.strip(), rows), problems


def _smiles(line: int, value: object, problems: list[Problem]) -> str | None:
    if value is _NOT_LITERAL:
        return None
    if not isinstance(value, str):
        problems.append((line, "SMILES must be a string literal"))
    elif not value.strip():
        problems.append((line, "SMILES must be a non-empty string"))
    else:
        return value
    return None


def _rows(line: int, value: object, problems: list[Problem]) -> list[list[float]] | None:
    if value is _NOT_LITERAL:
        return None
    text = "coordinates must be a non-empty list of rows of numbers, [[x, y, z], ...]"
    if not isinstance(value, list | tuple) or not value:
        problems.append((line, text))
        return None
    for i, row in enumerate(value):
        if not (isinstance(row, list | tuple) and len(row) == 3 and all(map(_number, row))):
            problems.append((line, f"{text}; row {i} is {row!r}, not three numbers"))
            return None
    return [[float(v) for v in row] for row in value]


def _number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _inert(node: ast.stmt) -> bool:
    """An import (judged by the generic import rules) or a docstring."""
    docstring = isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
    return docstring or isinstance(node, ast.Import | ast.ImportFrom)


def _assignment(node: ast.stmt) -> tuple[list[str], ast.expr] | None:
    """Names and value of ``a = b = value`` or ``a: T = value``; None for any other statement."""
    if isinstance(node, ast.Assign):
        targets, value = node.targets, node.value
    elif isinstance(node, ast.AnnAssign) and node.value is not None:
        targets, value = [node.target], node.value
    else:
        return None
    names = [t.id for t in targets if isinstance(t, ast.Name)]
    return (names, value) if len(names) == len(targets) else None


def _plain_annotation(node: ast.expr) -> bool:
    return all(isinstance(child, _ANNOTATION_NODES) for child in ast.walk(node))


def format_solution(smiles: str, coordinates: list[list[float]], decimals: int = 3) -> str:
    """Solution text (the task's code format) for ``smiles`` and heavy-atom ``coordinates``."""
    rows = ",\n".join(
        "    [" + ", ".join(f"{v:.{decimals}f}" for v in row) + "]" for row in coordinates
    )
    n = len(coordinates)
    return (
        f"SMILES: str = {json.dumps(smiles)}  # {n} heavy atoms\n\n"
        f"coordinates: list[list[float]] = [  # ({n}, 3), Angstrom, SMILES atom order\n"
        f"{rows},\n]\n"
    )
