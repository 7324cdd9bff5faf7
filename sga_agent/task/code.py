"""Reading a solution's code without running it: the error a static check raises, and the
helpers the generic checks (:mod:`sga_agent.parsing`) and a task's own ``check_solution``
share, so that both read the code the same way.

Standard library only: a task package imports it as part of the protocol.
"""

from __future__ import annotations

import ast
import re
import warnings
from collections.abc import Sequence

#: ``NAME = "`` (or ``NAME: T = "``) at a line start: such a literal is read as a raw string when
#: a backslash breaks the parse (a SMILES's ``C\N``).
_LITERAL_ASSIGNMENT = re.compile(r"""^(\s*[A-Za-z_]\w*\s*(?::[^=\n]*)?=\s*)(["'])""", re.M)
_MAX_PROBLEMS = 5
#: A problem of the code: ``(line, sentence)``, line 0 when no line applies.
Problem = tuple[int, str]


class CodeRejected(ValueError):
    """The code breaks a rule; the message says which and where, for the next prompt.

    Raised with a message, or with ``(line, sentence)`` problems (kept in ``problems``), which
    the message lists by line, up to five.
    """

    def __init__(self, problems: str | Sequence[Problem]) -> None:
        self.problems: list[Problem] = (
            [(0, problems)] if isinstance(problems, str) else list(problems)
        )
        super().__init__(_report(self.problems))


def parse_python(code: str) -> ast.Module:
    """``ast.parse``, quietly (nothing is run).

    A literal assigned at a line start whose backslash breaks the parse (a SMILES such as
    ``"C/C=C\\N"``) is read as a raw string.

    Raises
    ------
    CodeRejected
        The code is not valid Python; the message names the line.
    """
    attempts = [code]
    raw = _LITERAL_ASSIGNMENT.sub(r"\1r\2", code)
    if raw != code:
        attempts.append(raw)  # the literals read as raw strings
    errors: list[SyntaxError] = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", (DeprecationWarning, SyntaxWarning))
        for text in attempts:
            try:
                return ast.parse(text)
            except SyntaxError as error:
                errors.append(error)
            except (RecursionError, MemoryError):
                raise CodeRejected("the code is too deeply nested to be read") from None
    where = f"line {errors[0].lineno}: " if errors[0].lineno else ""
    raise CodeRejected(f"{where}the code is not valid Python ({errors[0].msg})")


def _report(problems: list[Problem]) -> str:
    unique = sorted(set(problems), key=lambda problem: (problem[0] == 0, problem))
    lines = [f"line {line}: {text}" if line else text for line, text in unique[:_MAX_PROBLEMS]]
    if len(unique) > _MAX_PROBLEMS:
        lines.append(f"(and {len(unique) - _MAX_PROBLEMS} more problems)")
    return "\n".join(lines)


def import_aliases(tree: ast.Module) -> dict[str, str]:
    """Names bound by imports, mapped to the dotted path they stand for."""
    found = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.asname:
                    found[alias.asname] = alias.name
                else:
                    top = alias.name.split(".")[0]
                    found[top] = top
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            for alias in node.names:
                found[alias.asname or alias.name] = f"{node.module}.{alias.name}"
    return found


def dotted_name(node: ast.expr, aliases: dict[str, str]) -> str | None:
    """``torch.nn.Module`` for an attribute chain rooted at an imported name, else None."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if isinstance(node, ast.Name) and node.id in aliases:
        return ".".join([aliases[node.id], *reversed(parts)])
    return None


def bound_names(tree: ast.AST) -> set[str]:
    """Every name ``tree`` binds: assignments, arguments, definitions, imports."""
    bound = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Name) and not isinstance(node.ctx, ast.Load):
            bound.add(node.id)
        elif isinstance(node, ast.arg):
            bound.add(node.arg)
        elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            bound.add(node.name)
        elif isinstance(node, ast.alias):
            bound.add((node.asname or node.name).split(".")[0])
    return bound
