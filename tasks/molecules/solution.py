"""Reading a proposal (SMILES and heavy-atom coordinates) from solution text, without running it.

A solution is a small python block::

    SMILES: str = "CC(=O)Nc1ccc(O)cc1"  # 11 heavy atoms
    coordinates: list[list[float]] = [[x, y, z], ...]  # (11, 3), Angstrom, SMILES atom order

given bare or inside a fenced code block (the last python block wins). The text is parsed with
:mod:`ast` and only literal values are read (``ast.literal_eval``): nothing is executed.
"""

from __future__ import annotations

import ast
import json
import re
import warnings
from dataclasses import dataclass

_FENCE = re.compile(r"```[ \t]*([A-Za-z0-9_+-]*)[^\n]*\n(.*?)(?:```|\Z)", re.S)


class ProposalError(ValueError):
    """The solution text does not define a usable proposal; the message is one-line feedback."""


@dataclass(frozen=True)
class Proposal:
    """A proposed molecule: SMILES and heavy-atom coordinates (Angstrom), as written."""

    smiles: str
    coordinates: list[list[float]]


_SMILES_LITERAL = re.compile(r"""^(\s*SMILES\s*(?::[^=\n]*)?=\s*)(["'])""", re.M)


def _parse(code: str) -> ast.Module:
    """``ast.parse`` without warnings about invalid escapes such as the ``\\C`` of a SMILES."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", (DeprecationWarning, SyntaxWarning))
        return ast.parse(code)


def extract_code(text: str) -> str:
    """The last ```python (or untagged) fenced block of ``text``; ``text`` itself if none."""
    blocks = [(tag.lower(), body) for tag, body in _FENCE.findall(text)]
    for tag, body in reversed(blocks):
        if tag in ("python", "py", "python3", ""):
            return body
    return text


def _literal_assignments(tree: ast.Module) -> dict[str, ast.expr]:
    """Top-level ``name = value`` and ``name: type = value`` assignments (the last one wins)."""
    found: dict[str, ast.expr] = {}
    for node in tree.body:
        if isinstance(node, ast.Assign) and node.value is not None:
            for target in node.targets:
                if isinstance(target, ast.Name):
                    found[target.id] = node.value
        elif (
            isinstance(node, ast.AnnAssign)
            and node.value is not None
            and isinstance(node.target, ast.Name)
        ):
            found[node.target.id] = node.value
    return found


def _number(value: object) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value)


def parse_solution(text: str) -> Proposal:
    """Read ``SMILES`` and ``coordinates`` from solution text.

    Raises
    ------
    ProposalError
        The code does not parse, a name is missing, or a value is not a literal of the right
        shape (a string; a list of ``[x, y, z]`` number rows).
    """
    code = extract_code(text)
    try:
        tree = _parse(code)
    except SyntaxError as error:
        # SMILES use backslashes for double-bond geometry; "\N" in a plain string literal is
        # a broken Python escape. Read such a SMILES literal as a raw string instead.
        raw = _SMILES_LITERAL.sub(r"\1r\2", code)
        try:
            tree = _parse(raw) if raw != code else None
        except SyntaxError:
            tree = None
        if tree is None:
            raise ProposalError(
                f"the code is not valid Python (line {error.lineno}: {error.msg})"
            ) from None
    values = _literal_assignments(tree)
    missing = [name for name in ("SMILES", "coordinates") if name not in values]
    if missing:
        raise ProposalError(
            "the code must assign "
            + " and ".join(f"`{m}`" for m in missing)
            + ' at top level, e.g. SMILES = "CCO..." and coordinates = [[x, y, z], ...]'
        )
    try:
        smiles = ast.literal_eval(values["SMILES"])
    except (ValueError, TypeError, SyntaxError, MemoryError, RecursionError):
        raise ProposalError("`SMILES` must be a plain string literal") from None
    if not isinstance(smiles, str) or not smiles.strip():
        raise ProposalError("`SMILES` must be a non-empty string")
    try:
        rows = ast.literal_eval(values["coordinates"])
    except (ValueError, TypeError, SyntaxError, MemoryError, RecursionError):
        raise ProposalError(
            "`coordinates` must be a literal list of [x, y, z] rows of numbers "
            "(no function calls, variables or arithmetic)"
        ) from None
    if not isinstance(rows, list | tuple) or not rows:
        raise ProposalError("`coordinates` must be a non-empty list of [x, y, z] rows")
    coordinates: list[list[float]] = []
    for i, row in enumerate(rows):
        numbers = [_number(v) for v in row] if isinstance(row, list | tuple) else [None]
        if len(numbers) != 3 or any(v is None for v in numbers):
            raise ProposalError(
                f"`coordinates` row {i} is {row!r}; every row must be three numbers [x, y, z]"
            )
        coordinates.append([float(v) for v in numbers if v is not None])
    return Proposal(smiles=smiles.strip(), coordinates=coordinates)


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
