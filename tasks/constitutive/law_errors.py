"""Why a law's code failed, in one line for the model: the cause, the line and the fix.

A proposed law that fails while it is loaded, built or captured raises whatever torch or Python
raises, and that message alone rarely tells a model what to change. :func:`explain` finds the
law's own line in the traceback (the code is compiled under the file name :data:`LAW_FILENAME`),
quotes it, and looks the message up in :data:`HINTS`: one row per known error, a regular
expression on ``"ErrorType: message"`` with the cause in plain words and the fix. A few rows
complete their fix from the code or from torch's own names ("did you mean").
"""

from __future__ import annotations

import ast
import difflib
import re
import sys
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from types import ModuleType

import torch
import torch.nn.functional

from sga_agent.task.code import bound_names

#: The file name a law's code is compiled under, so that its frames can be found.
LAW_FILENAME = "<law>"
#: Longest quote of the law's line and of torch's message, in characters.
MAX_QUOTE_CHARS, MAX_MESSAGE_CHARS = 60, 90

#: Imports that define a name a law commonly uses without importing it.
IMPORTS = {
    "torch": "import torch",
    "nn": "import torch.nn as nn",
    "nnf": "import torch.nn.functional as nnf",
    "functional": "import torch.nn.functional as functional",
    "math": "import math",
}
#: Namespaces searched for a misspelt or misplaced torch function.
_NAMESPACES: dict[str, ModuleType] = {
    "torch": torch,
    "torch.linalg": torch.linalg,
    "torch.nn.functional": torch.nn.functional,
}
#: Batched replacements of torch functions that take one matrix only.
_BATCHED = {"trace": "torch.diagonal(A, dim1=-2, dim2=-1).sum(-1)"}


@dataclass(frozen=True)
class Hint:
    """One known error: ``pattern`` is searched in ``"ErrorType: message"``; ``cause`` and
    ``fix`` may name the pattern's groups (``{name}``), and ``more`` writes the rest of the fix
    from the match and the law's code. ``quoted``: whether the message is worth quoting (not
    when it speaks of the trace's internals)."""

    pattern: str
    cause: str
    fix: str
    more: Callable[[re.Match[str], str], str] | None = None
    quoted: bool = True


def _closest_attribute(match: re.Match[str], code: str) -> str:
    """Where a function missing from one torch namespace is, or the names closest to it."""
    module, name = match["module"], match["attribute"]
    if name in _BATCHED:
        return f"for a batch use {_BATCHED[name]}"
    elsewhere = [f"{prefix}.{name}" for prefix, namespace in _NAMESPACES.items()
                 if prefix != module and hasattr(namespace, name)]  # fmt: skip
    if elsewhere:
        return f"it exists as {' and '.join(elsewhere)}"
    namespace = sys.modules.get(module, torch)
    close = _did_you_mean(name, dir(namespace), f"{module}.")
    return close or "look for it in torch, torch.linalg or torch.nn.functional"


def _closest_method(match: re.Match[str], code: str) -> str:
    close = _did_you_mean(match["attribute"], dir(torch.Tensor), ".")
    return close or "use a torch function of the tensor instead"


def _did_you_mean(name: str, candidates: list[str], prefix: str) -> str:
    public = [candidate for candidate in candidates if not candidate.startswith("_")]
    close = difflib.get_close_matches(name, public, n=2, cutoff=0.6)
    return "did you mean " + " or ".join(prefix + c for c in close) + "?" if close else ""


def _undefined_name(match: re.Match[str], code: str) -> str:
    """The import that defines the name, the ``self.`` it lacks, or the closest defined name."""
    name = match["name"]
    if name in IMPORTS:
        return f"add `{IMPORTS[name]}` at the top of the code"
    tree = _parse(code)
    attributes = {node.attr for node in ast.walk(tree) if isinstance(node, ast.Attribute)
                  and isinstance(node.value, ast.Name) and node.value.id == "self"}  # fmt: skip
    if name in attributes:
        return f"{name} is an attribute of the law: write self.{name}"
    if name in _init_arguments(tree):
        return (
            f"{name} is an argument of __init__, which forward cannot see; keep it in __init__ "
            f"(self.{name} = nn.Parameter(torch.tensor({name}))) and write self.{name}"
        )
    close = _did_you_mean(name, sorted(bound_names(tree) - {name}), "")
    return close or f"define {name} before this line (a parameter is self.{name})"


def _integer_defaults(match: re.Match[str], code: str) -> str:
    """The ``__init__`` arguments whose default is an integer, written as floats."""
    tree = _parse(code)
    found = [f"{name}={value} -> {name}={float(value)!r}"
             for name, value in _init_arguments(tree).items()
             if isinstance(value, int) and not isinstance(value, bool)]  # fmt: skip
    return f" ({', '.join(found)})" if found else ""


#: Known errors of a law's code, first match wins.
HINTS: tuple[Hint, ...] = (
    Hint(
        r"trace: expected a matrix|expected a matrix, but got tensor with dim",
        "torch.trace works on one matrix, not on a batch of them (F is (B, 3, 3))",
        "use torch.diagonal(A, dim1=-2, dim2=-1).sum(-1), the trace of each matrix",
    ),
    Hint(
        r"Only Tensors of floating point and complex dtype can require gradients",
        "a parameter was built from an integer tensor, which cannot be fitted (its default "
        "is an int)",
        "write its default as a float, 1.0 not 1",
        _integer_defaults,
    ),
    Hint(
        r"expected scalar type|to have the same dtype|must have the same dtype"
        r"|Found dtype \w+ but expected|expected (?:both|all) .*same dtype",
        "float32 and float64 tensors meet in one operation (a tensor made without dtype= is "
        "float32, F may be float64)",
        "create tensors with dtype=F.dtype, or torch.eye(3, dtype=F.dtype)",
    ),
    Hint(
        r"Boolean value of Tensor with more than one value is ambiguous",
        "an if (or and, or, not) on a tensor of many values, one per particle, has no single "
        "truth value",
        "choose per particle with torch.where(condition, a, b) instead of an if",
    ),
    Hint(
        r"data-dependent|Data dependent|DataDependent|unallocated storage|item\(\)"
        r"|_local_scalar_dense",
        "forward reads a tensor's value (an if on a tensor, .item(), float() or bool() of "
        "it), which cannot be captured",
        "use torch.where(condition, a, b) instead of an if, and keep every value a tensor",
        quoted=False,
    ),
    Hint(
        r"(?i)numpy|__array__",
        "forward converts a tensor to NumPy, which cannot be captured",
        "use torch operations on tensors only",
        quoted=False,
    ),
    Hint(
        r"must be batches of square matrices",
        "det, inverse and solve need square matrices, and these are not",
        "pass (B, 3, 3) matrices: F is (B, 3, 3), a slice such as F[:, :2] is (B, 2, 3)",
    ),
    Hint(
        r"must match the size of tensor|shapes cannot be multiplied|Expected size for first "
        r"two dimensions|size mismatch|mismatch in shape|cannot be broadcast|Incompatible shapes"
        r"|einsum\(\).*(?:operand|subscript)",
        "the shapes of two tensors do not fit together",
        "F is (B, 3, 3): a value per particle is (B, 1, 1) (keepdim=True or .view(-1, 1, 1)), "
        "a 3-vector (B, 3, 1); A @ B needs (B, n, k) @ (B, k, m)",
    ),
    Hint(
        r"Dimension out of range",
        "a dim argument is beyond the tensor's dimensions",
        "F is (B, 3, 3): its dims are 0 (particles), 1 and 2 (or -2 and -1)",
    ),
    Hint(
        r"view size is not compatible|Cannot view a tensor",
        ".view needs contiguous memory, which a transposed or expanded tensor lacks",
        "use .reshape(...) instead of .view(...)",
    ),
    Hint(
        r"only one element tensors can be converted to Python scalars|Could not infer dtype",
        "a tensor of many values is used as one number (torch.tensor of tensors, math.* or "
        "float() of it)",
        "keep values tensors: torch.stack([a, b], dim=-1) puts tensors together, torch.exp "
        "replaces math.exp",
    ),
    Hint(
        r"svd\(\) got an unexpected keyword argument '(?P<keyword>\w+)'",
        "torch.svd takes some=, torch.linalg.svd full_matrices=, and neither is needed",
        "write U, S, Vh = torch.linalg.svd(F): F = U @ torch.diag_embed(S) @ Vh",
    ),
    Hint(
        r"'torch\.return_types\.(?:linalg_)?svd' object has no attribute '(?P<attribute>\w+)'",
        "the result of torch.linalg.svd has the fields U, S and Vh (not {attribute})",
        "unpack it as U, S, Vh = torch.linalg.svd(F); V is Vh.transpose(-2, -1)",
    ),
    Hint(
        r"(?:too many|not enough) values to unpack \(expected (?P<expected>\d+)",
        "the names on the left of = are not as many as the values returned",
        "torch.linalg.svd returns U, S, Vh; torch.linalg.eigh returns L, Q; torch.linalg.qr "
        "returns Q, R",
    ),
    Hint(
        r"module '(?P<module>torch[\w.]*)' has no attribute '(?P<attribute>\w+)'",
        "{module}.{attribute} does not exist",
        "",
        _closest_attribute,
    ),
    Hint(
        r"'(?:\w*Tensor|Parameter)' object has no attribute '(?P<attribute>\w+)'",
        "tensors have no method .{attribute}",
        "",
        _closest_method,
    ),
    Hint(
        r"name '(?P<name>\w+)' is not defined",
        "the name {name} is not defined where it is used",
        "",
        _undefined_name,
    ),
    Hint(
        r"'(?P<kind>float|int)' object has no attribute '(?P<attribute>\w+)'",
        "a Python {kind} has no method .{attribute}",
        "make it a tensor first, torch.as_tensor(x, dtype=F.dtype), or use math for numbers",
    ),
    Hint(
        r"before Module\.__init__\(\) call",
        "__init__ sets a parameter or module before nn.Module is initialized",
        "call super().__init__() first in __init__",
    ),
    Hint(
        r"must be Tensor, not (?P<kind>\w+)",
        "a torch function got a Python {kind} where it needs a tensor",
        "use math for plain numbers, or make it a tensor with torch.as_tensor(x, dtype=F.dtype)",
    ),
    Hint(
        r"received an invalid combination of arguments|got an unexpected keyword argument",
        "a torch function was called with arguments it does not take",
        "pass only what it documents; a batch of identities is "
        "torch.eye(3, dtype=F.dtype).expand_as(F)",
    ),
)


def describe_error(error: BaseException, limit: int | None = None) -> str:
    """``ErrorType: first line of the message``, the message cut at ``limit`` characters."""
    lines = str(error).strip().splitlines()
    message = lines[0] if lines else ""
    if limit is not None:
        message = _shorten(message, limit).rstrip(" .")
    return f"{type(error).__name__}: {message}".rstrip(": ")


def explain(error: BaseException, code: str) -> str:
    """The cause, the law's line and the fix of ``error``, raised by running ``code``."""
    return explain_at(error, law_line(error), code)


def explain_at(error: BaseException, line: int | None, code: str, raised: bool = True) -> str:
    """:func:`explain` for an error known to come from line ``line`` of ``code``; ``raised``
    False: nothing raised it there, the line only does what ``error`` describes.

    Cause, line and fix come first, the error's own message last (a reason cut short loses
    that first)."""
    described = describe_error(error, MAX_MESSAGE_CHARS)
    where = quote_line(code, line)
    hint = find_hint(f"{type(error).__name__}: {error}")
    if hint is None:
        return f"{described}, at {where}" if where else described
    found, match = hint
    groups = match.groupdict()
    fix = found.fix.format(**groups) + (found.more(match, code) if found.more else "")
    parts = [found.cause.format(**groups), f"At {where}" if where else "", f"Fix: {fix}"]
    if raised and found.quoted:
        parts.append(f"Raised {described}")
    return " ".join(part if part.endswith(("?", ".")) else part + "." for part in parts if part)


def find_hint(text: str) -> tuple[Hint, re.Match[str]] | None:
    """The first row of :data:`HINTS` whose pattern is found in ``text``, with its match."""
    for hint in HINTS:
        match = re.search(hint.pattern, text)
        if match:
            return hint, match
    return None


def law_line(error: BaseException) -> int | None:
    """The line of the law's code that raised ``error``: its innermost frame in the law (read
    from the frames, no source file is opened)."""
    frames = traceback.walk_tb(error.__traceback__)
    lines = [line for frame, line in frames if frame.f_code.co_filename == LAW_FILENAME]
    return lines[-1] if lines else None


def stack_line(stack_trace: str | None) -> int | None:
    """The law's innermost line in a recorded stack trace (as ``make_fx`` keeps per node)."""
    found = re.findall(rf'File "{re.escape(LAW_FILENAME)}", line (\d+)', stack_trace or "")
    return int(found[-1]) if found else None


def quote_line(code: str, line: int | None) -> str:
    """``line 14 (`tr = torch.trace(F)`)``, or "" when the line is unknown."""
    lines = code.splitlines()
    if line is None or not 1 <= line <= len(lines):
        return ""
    return f"line {line} (`{_shorten(lines[line - 1].strip(), MAX_QUOTE_CHARS)}`)"


def _shorten(text: str, limit: int) -> str:
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _parse(code: str) -> ast.Module:
    try:
        return ast.parse(code)
    except SyntaxError:
        return ast.Module(body=[], type_ignores=[])


def _init_arguments(tree: ast.Module) -> dict[str, object]:
    """The ``__init__`` arguments of the code's classes, with their constant defaults."""
    found: dict[str, object] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef) and node.name == "__init__":
            arguments = node.args.posonlyargs + node.args.args
            defaults: list[ast.expr | None] = [None] * len(arguments)
            defaults[len(arguments) - len(node.args.defaults) :] = node.args.defaults
            pairs = zip(arguments + node.args.kwonlyargs, defaults + node.args.kw_defaults,
                        strict=True)  # fmt: skip
            for argument, default in pairs:
                value = default.value if isinstance(default, ast.Constant) else None
                found[argument.arg] = value
    found.pop("self", None)
    return found
