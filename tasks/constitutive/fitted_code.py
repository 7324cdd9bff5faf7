"""A law's code with its fitted parameter values written in, for people to read.

The search reports a law by its code, whose constants are the ones it was *proposed* with;
the inner optimization then fits them. :func:`with_fitted_values` writes the fitted values
where the code sets each parameter's starting value: the default of the ``__init__``
argument that ``self.NAME = nn.Parameter(torch.tensor(ARG))`` starts from, or the literal
in its place. The code is only parsed, never run; everything else in it is left as written.
"""

from __future__ import annotations

import ast
import math
from collections.abc import Mapping

CLASS_NAME = "Physics"
_TENSOR_FACTORIES = frozenset({"tensor", "as_tensor", "scalar_tensor"})


def with_fitted_values(code: str, parameters: Mapping[str, float]) -> str:
    """``code`` with each scalar parameter's starting value replaced by ``parameters[name]``.

    Parameters the code does not set in a form recognised here (and code that does not
    parse) are left unchanged.

    Examples
    --------
    >>> code = '''
    ... class Physics(nn.Module):
    ...     def __init__(self, log_e: float = 10.0):
    ...         super().__init__()
    ...         self.log_e = nn.Parameter(torch.tensor(log_e))
    ... '''
    >>> "log_e: float = 13.02" in with_fitted_values(code, {"log_e": 13.02})
    True
    """
    try:
        tree = ast.parse(code)
    except (SyntaxError, ValueError):
        return code
    edits: dict[tuple[int, int, int, int], str] = {}
    for init in _initialisers(tree):
        defaults = _defaults(init.args)
        for name, start in _parameter_starts(init):
            value = parameters.get(name)
            if not isinstance(value, int | float) or not math.isfinite(value):
                continue
            target = defaults.get(start.id) if isinstance(start, ast.Name) else start
            if _is_number(target):
                edits[_span(target)] = _number(float(value))
    return _apply(code, edits)


def _is_number(node: ast.expr | None) -> bool:
    """Whether ``node`` is a number literal, signed or not (``-0.63`` is a unary minus on a
    constant in the syntax tree)."""
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd):
        node = node.operand
    return (isinstance(node, ast.Constant) and isinstance(node.value, int | float)
            and not isinstance(node.value, bool))  # fmt: skip


def _initialisers(tree: ast.Module) -> list[ast.FunctionDef]:
    return [
        item
        for node in tree.body
        if isinstance(node, ast.ClassDef) and node.name == CLASS_NAME
        for item in node.body
        if isinstance(item, ast.FunctionDef) and item.name == "__init__"
    ]


def _defaults(args: ast.arguments) -> dict[str, ast.expr]:
    """Argument name -> its default expression."""
    positional = args.posonlyargs + args.args
    first = len(positional) - len(args.defaults)
    pairs = zip(positional[first:], args.defaults, strict=True)
    found = {arg.arg: default for arg, default in pairs}
    for arg, default in zip(args.kwonlyargs, args.kw_defaults, strict=True):
        if default is not None:
            found[arg.arg] = default
    return found


def _parameter_starts(init: ast.FunctionDef) -> list[tuple[str, ast.expr]]:
    """(parameter name, the expression its tensor starts from) of each
    ``self.NAME = nn.Parameter(torch.tensor(EXPR))`` in ``__init__`` (``float(EXPR)`` too)."""
    starts = []
    for node in ast.walk(init):
        if not (isinstance(node, ast.Assign) and len(node.targets) == 1):
            continue
        target, value = node.targets[0], node.value
        if not (
            isinstance(target, ast.Attribute)
            and isinstance(target.value, ast.Name)
            and target.value.id == "self"
        ):
            continue
        start = _tensor_argument(_single_argument(value, "Parameter"))
        if start is not None:
            starts.append((target.attr, start))
    return starts


def _single_argument(node: ast.expr | None, function: str) -> ast.expr | None:
    """The first argument of a call to ``function`` (``nn.Parameter(x)``, ``Parameter(x)``)."""
    if not (isinstance(node, ast.Call) and node.args):
        return None
    called = node.func
    name = called.attr if isinstance(called, ast.Attribute) else getattr(called, "id", None)
    return node.args[0] if name == function else None


def _tensor_argument(node: ast.expr | None) -> ast.expr | None:
    """EXPR of ``torch.tensor(EXPR, ...)``, unwrapping ``float(EXPR)``."""
    if not (isinstance(node, ast.Call) and node.args):
        return None
    called = node.func
    name = called.attr if isinstance(called, ast.Attribute) else getattr(called, "id", None)
    if name not in _TENSOR_FACTORIES:
        return None
    start = node.args[0]
    inner = _single_argument(start, "float")
    return inner if inner is not None else start


def _span(node: ast.expr) -> tuple[int, int, int, int]:
    assert node.end_lineno is not None and node.end_col_offset is not None
    return (node.lineno, node.col_offset, node.end_lineno, node.end_col_offset)


def _number(value: float) -> str:
    """Short but exact enough to reproduce the loss: 8 significant digits."""
    text = f"{value:.8g}"
    return text if any(c in text for c in ".en") else text + ".0"


def _apply(code: str, edits: dict[tuple[int, int, int, int], str]) -> str:
    """Replace each (line, column, end line, end column) span (1-based lines, columns in
    UTF-8 bytes as ``ast`` reports them) by its text, last first."""
    lines = [line.encode() for line in code.splitlines(keepends=True)]
    for (line, column, end_line, end_column), text in sorted(edits.items(), reverse=True):
        head = lines[line - 1][:column]
        tail = lines[end_line - 1][end_column:]
        lines[line - 1 : end_line] = [head + text.encode() + tail]
    return b"".join(lines).decode()
