"""Reading a model's answer the way a person would, before the strict checks of
:mod:`sga_agent.parsing`.

Models write good code with small slips a reader fixes without a second thought; rejecting the
answer for them wastes a paid proposal and tells the model something untrue. :func:`read_answer`
takes the code block that defines what the task's code template defines (not blindly the
last one), and for code tasks (``kind == "equation"``):

- drops a usage example after the solution (``if __name__ == "__main__":``, ``print(...)``,
  ``law = Physics()`` and what follows from it);
- adds the standard imports the code uses without importing (``torch``, ``nn``, ``math``,
  ``np``, the ``typing`` names of its hints);
- writes an integer starting value of a parameter as a float (``E: float = 200000`` becomes
  ``200000.0``; ``torch.tensor(1)`` inside ``nn.Parameter`` becomes ``torch.tensor(1.0)``);
- reads ``torch.trace(X)``, which works on one matrix, as what the author of a law over a
  batch F (B, 3, 3) meant by it: the trace of each matrix, kept as (B, 1, 1);
- drops casts to a precision (``.to(torch.float32)``, ``.double()``): the simulation chooses
  the precision, and a cast tensor meets F's in the next product.

Each change is listed in :attr:`Reading.fixes`, in words the model is shown. Nothing here runs
the code: it is read through its syntax tree, and edited as text so that its comments stay.
An answer cut off at the token limit inside its code is named as such.
"""

from __future__ import annotations

import ast
import re
import warnings
from dataclasses import dataclass, field

from sga_agent.parsing import ParsedResponse, parse_response
from sga_agent.task.code import bound_names

#: Imports added when the code uses the name without binding it (equation tasks).
STANDARD_IMPORTS: dict[str, str] = {
    "torch": "import torch",
    "nn": "import torch.nn as nn",
    "math": "import math",
    "np": "import numpy as np",
    "numpy": "import numpy",
}
#: ``typing`` names models use in hints without importing them.
TYPING_NAMES = frozenset({"Any", "Dict", "List", "Optional", "Sequence", "Tuple", "Union"})
#: The trace of each matrix of a batch (B, 3, 3), as (B, 1, 1).
BATCHED_TRACE = "torch.diagonal({}, dim1=-2, dim2=-1).sum(-1)[..., None, None]"
#: The floating types a precision cast names.
_FLOAT_TYPES = frozenset({
    "torch.float32", "torch.float64", "torch.float", "torch.double", "torch.half",
    "torch.float16", "torch.bfloat16",
})  # fmt: skip
#: Annotations under which an integer default is meant as an integer.
_INTEGER_HINTS = frozenset({"int", "bool"})
_THINK = re.compile(r"<think(?:ing)?>(.*?)(?:</think(?:ing)?>|\Z)", re.S | re.I)
_OPENING_THINK = re.compile(r"<think(?:ing)?>", re.I)
_CLOSING_THINK = re.compile(r"</think(?:ing)?>", re.I)


@dataclass(frozen=True)
class Reading:
    """What was read from an answer.

    Parameters
    ----------
    code : str or None
        The code to check and run (None: the answer has none usable).
    problem : str
        Why there is no usable code (empty when there is).
    fixes : list of str
        The slips fixed on the way, one sentence each, for the model's feedback.
    parsed : ParsedResponse
        The answer's sections and code blocks.
    reasoning : str
        The answer's own ``<think>`` part, if it wrote one.
    """

    code: str | None
    problem: str = ""
    fixes: list[str] = field(default_factory=list)
    parsed: ParsedResponse | None = None
    reasoning: str = ""


def read_answer(text: str, kind: str, template: str, finish_reason: str = "") -> Reading:
    """The code of a model's answer, its slips fixed; see the module docstring.

    Parameters
    ----------
    text : str
        The answer.
    kind : str
        The task kind: only ``"equation"`` code gets imports and float constants fixed.
    template : str
        The task's code template: the block defining its names is the solution.
    finish_reason : str
        The provider's finish reason; "length" with an unclosed code block is a cut-off answer.
    """
    reasoning, visible = split_reasoning(text)
    parsed = parse_response(visible)
    if not parsed.blocks:
        if finish_reason == "length":
            return Reading(None, cut_off_problem(), parsed=parsed, reasoning=reasoning)
        problem = "the answer has no ```python code block; put the code in one block"
        return Reading(None, problem, parsed=parsed, reasoning=reasoning)
    names = template_names(template)
    index = _solution_block(parsed.blocks, names)
    if parsed.open_block and index == len(parsed.blocks) - 1 and finish_reason == "length":
        return Reading(None, cut_off_problem(), parsed=parsed, reasoning=reasoning)
    code = parsed.blocks[index]
    fixes = []
    if len(parsed.blocks) > 1 and index != len(parsed.blocks) - 1:
        fixes.append(
            f"the answer has {len(parsed.blocks)} code blocks; block {index + 1}, which "
            f"defines {', '.join(sorted(names & _defined(code))) or 'the solution'}, was taken"
        )
    if kind == "equation":
        code, more = fix_code(code, names)
        fixes += more
    return Reading(code, fixes=fixes, parsed=parsed, reasoning=reasoning)


def split_reasoning(text: str) -> tuple[str, str]:
    """An answer's ``<think>`` part and the rest. A closing tag with no opening one (the
    chat template of QwQ and some DeepSeek-R1 servers opens it) closes what came before."""
    closing = _CLOSING_THINK.search(text)
    if closing and not _OPENING_THINK.search(text[: closing.start()]):
        text = "<think>" + text
    reasoning = "\n\n".join(part.strip() for part in _THINK.findall(text)).strip()
    return reasoning, _THINK.sub("", text)


def cut_off_problem() -> str:
    """What a cut-off answer is told."""
    return (
        "the answer was cut off at the token limit before its code block was complete; "
        "keep the analysis and plan short and write the whole code block"
    )


def template_names(template: str) -> set[str]:
    """The names a code template defines at its top level (classes, functions, assigned
    names)."""
    return _defined(template)


def fix_code(code: str, names: set[str]) -> tuple[str, list[str]]:
    """``code`` with its usage example dropped, integer starting values written as floats,
    ``torch.trace`` of a batch read as each matrix's trace, precision casts dropped and missing
    standard imports added; the fixes, one sentence each. Code that does not parse is returned
    unchanged (the checks name its syntax error)."""
    fixes: list[str] = []
    for step in (_drop_usage, _float_defaults, _batched_traces, _no_precision_casts, _add_imports):
        tree = _parse(code)
        if tree is None:
            break
        code, fix = step(code, tree, names)
        if fix:
            fixes.append(fix)
    return code, fixes


# ---------------------------------------------------------------------- choosing the block


def _solution_block(blocks: tuple[str, ...], names: set[str]) -> int:
    """The index of the block defining most of ``names`` (the last one on a tie)."""
    scores = [len(names & _defined(block)) for block in blocks]
    best = max(scores)
    return max(i for i, score in enumerate(scores) if score == best)


def _defined(code: str) -> set[str]:
    tree = _parse(code)
    return _defined_in(tree) if tree is not None else set()


def _defined_in(tree: ast.Module) -> set[str]:
    found = set()
    for node in tree.body:
        if isinstance(node, ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            found.add(node.name)
        elif isinstance(node, ast.Assign | ast.AnnAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            found |= {t.id for t in targets if isinstance(t, ast.Name)}
    return found


# ---------------------------------------------------------------------- fixing the code


def _drop_usage(code: str, tree: ast.Module, names: set[str]) -> tuple[str, str]:
    """Drop the top-level statements after the solution that nothing of the solution reads:
    a usage example (``law = Physics()``, ``print(...)``, ``if __name__ == "__main__":``)."""
    defining = [
        i
        for i, node in enumerate(tree.body)
        if isinstance(node, ast.ClassDef | ast.FunctionDef) and node.name in names
    ]
    if not defining:
        return code, ""
    definitions = (ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)
    read: set[str] = set()  # the global names the definitions read
    for node in tree.body:
        if isinstance(node, definitions):
            loads = {n.id for n in ast.walk(node) if isinstance(n, ast.Name) and _reads(n)}
            read |= loads - bound_names(node)
    dropped = []
    for node in tree.body[defining[-1] + 1 :]:
        if isinstance(node, (ast.Import, ast.ImportFrom, *definitions)) or _is_docstring(node):
            continue
        stored = {n.id for n in ast.walk(node) if isinstance(n, ast.Name) and not _reads(n)}
        if _is_main_guard(node) or not stored & read:
            dropped.append(node)
    if not dropped:
        return code, ""
    lines = code.splitlines()
    gone = {i for node in dropped for i in range(node.lineno - 1, node.end_lineno or node.lineno)}
    kept = "\n".join(line for i, line in enumerate(lines) if i not in gone).rstrip() + "\n"
    return kept, (
        f"the usage example after the solution (line {dropped[0].lineno} on) was left out: "
        "the code block holds only the solution"
    )


def _is_main_guard(node: ast.stmt) -> bool:
    return isinstance(node, ast.If) and "__main__" in ast.unparse(node.test)


def _is_docstring(node: ast.stmt) -> bool:
    return (
        isinstance(node, ast.Expr)
        and isinstance(node.value, ast.Constant)
        and isinstance(node.value.value, str)
    )


def _float_defaults(code: str, tree: ast.Module, names: set[str]) -> tuple[str, str]:
    """Integer starting values of parameters written as floats."""
    edits: list[ast.Constant] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef) and node.name == "__init__":
            edits += _integer_defaults(node.args)
        elif _is_parameter_call(node):
            for inner in ast.walk(node):
                if _is_tensor_call(inner):
                    edits += [arg for arg in inner.args[:1] if _is_integer(arg)]
    if not edits:
        return code, ""
    fixed = _replaced(code, [(c, f"{c.value}.0") for c in edits])
    shown = sorted({str(c.value) for c in edits}, key=len)[:3]
    return fixed, (
        f"integer starting values ({', '.join(shown)}) were written as floats: a fitted "
        "parameter must be a float (write 1.0, not 1)"
    )


def _batched_traces(code: str, tree: ast.Module, names: set[str]) -> tuple[str, str]:
    """``torch.trace(X)``, meant per particle on a batch (B, 3, 3), as the trace of each
    matrix, kept broadcastable as (B, 1, 1) the way the scalar it was taken for is used."""
    calls = [node for node in ast.walk(tree) if _is_trace(node)]
    if not calls:
        return code, ""
    line = calls[0].lineno
    for _ in range(len(calls)):
        call = next((node for node in ast.walk(tree) if _is_trace(node)), None)
        if call is None:
            break
        text = BATCHED_TRACE.format(_source(code, call.args[0]))  # type: ignore[attr-defined]
        code = _replaced(code, [(call, text)])
        tree = _parse(code) or tree
    return code, (
        f"torch.trace works on one matrix, so torch.trace(...) of a batch (line {line}) was "
        f"read as the trace of each matrix, {BATCHED_TRACE.format('A')}"
    )


def _is_trace(node: ast.AST) -> bool:
    return (
        isinstance(node, ast.Call)
        and ast.unparse(node.func) == "torch.trace"
        and len(node.args) == 1
        and not node.keywords
    )


def _no_precision_casts(code: str, tree: ast.Module, names: set[str]) -> tuple[str, str]:
    """Casts to a floating precision dropped, one at a time (they may nest): the simulation
    chooses the precision, and a tensor cast to another meets F's in the next product."""
    casts = [node for node in ast.walk(tree) if _is_precision_cast(node)]
    if not casts:
        return code, ""
    first = f"`{_source(code, casts[0])}` (line {casts[0].lineno})"
    for _ in range(len(casts)):
        cast = next((node for node in ast.walk(tree) if _is_precision_cast(node)), None)
        if cast is None:
            break
        code = _replaced(code, [(cast, _operand(code, cast.func.value))])  # type: ignore[attr-defined]
        tree = _parse(code) or tree
    return code, (
        f"precision casts such as {first} were dropped: the simulation chooses the "
        "precision (make tensors with dtype=F.dtype)"
    )


def _operand(code: str, node: ast.expr) -> str:
    """``node``'s text, in parentheses unless it binds tighter than any operator."""
    text = _source(code, node)
    atoms = (ast.Name, ast.Attribute, ast.Call, ast.Subscript, ast.Constant)
    return text if isinstance(node, atoms) else f"({text})"


def _is_precision_cast(node: ast.AST) -> bool:
    if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)):
        return False
    method, args = node.func.attr, [*node.args, *(k.value for k in node.keywords)]
    if method in ("float", "double") and not args:
        return True
    return method == "to" and len(args) == 1 and ast.unparse(args[0]) in _FLOAT_TYPES


def _integer_defaults(args: ast.arguments) -> list[ast.Constant]:
    positional = [*args.posonlyargs, *args.args]
    pairs = list(
        zip(positional[len(positional) - len(args.defaults) :], args.defaults, strict=True)
    )
    pairs += [
        (a, d) for a, d in zip(args.kwonlyargs, args.kw_defaults, strict=True) if d is not None
    ]
    found = []
    for arg, default in pairs:
        hint = ast.unparse(arg.annotation) if arg.annotation is not None else ""
        if _is_integer(default) and hint not in _INTEGER_HINTS:
            found.append(default)
    return found


def _is_integer(node: ast.AST | None) -> bool:
    return (
        isinstance(node, ast.Constant)
        and type(node.value) is int
        and node.end_col_offset is not None
    )


def _is_parameter_call(node: ast.AST) -> bool:
    return isinstance(node, ast.Call) and ast.unparse(node.func).endswith("Parameter")


def _is_tensor_call(node: ast.AST) -> bool:
    return isinstance(node, ast.Call) and ast.unparse(node.func) in ("torch.tensor", "tensor")


def _add_imports(code: str, tree: ast.Module, names: set[str]) -> tuple[str, str]:
    """Standard imports the code uses but lacks, added at its top."""
    bound = bound_names(tree)
    loaded = {
        n.id for n in ast.walk(tree) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Load)
    }
    missing = [STANDARD_IMPORTS[name] for name in STANDARD_IMPORTS if name in loaded - bound]
    hints = sorted((loaded - bound) & TYPING_NAMES)
    if hints:
        missing.append(f"from typing import {', '.join(hints)}")
    if "nn" in loaded - bound and "torch" not in bound and "import torch" not in missing:
        missing.insert(0, "import torch")
    if not missing:
        return code, ""
    lines = code.splitlines(keepends=True)
    at = _import_position(tree)
    added = "".join(line + "\n" for line in missing)
    fixed = "".join(lines[:at]) + added + "".join(lines[at:])
    listed = ", ".join(f"`{line}`" for line in missing)
    return fixed, f"the code used names it never imported; added {listed}"


def _source(code: str, node: ast.AST) -> str:
    return ast.get_source_segment(code, node) or ast.unparse(node)


def _replaced(code: str, edits: list[tuple[ast.AST, str]]) -> str:
    """``code`` with each node's text replaced (nodes that do not overlap)."""
    lines = code.splitlines(keepends=True)
    starts = [0]
    for line in lines:
        starts.append(starts[-1] + len(line))

    def offset(line: int, byte_column: int) -> int:  # ast columns count UTF-8 bytes
        return starts[line - 1] + len(lines[line - 1].encode()[:byte_column].decode())

    spans = sorted(
        ((offset(n.lineno, n.col_offset), offset(n.end_lineno, n.end_col_offset), text)  # type: ignore[attr-defined]
         for n, text in edits),
        reverse=True,
    )  # fmt: skip
    for start, end, text in spans:
        code = code[:start] + text + code[end:]
    return code


def _reads(node: ast.Name) -> bool:
    return isinstance(node.ctx, ast.Load)


def _import_position(tree: ast.Module) -> int:
    """The line index after the module docstring and ``from __future__`` imports."""
    at = 0
    for node in tree.body:
        future = isinstance(node, ast.ImportFrom) and node.module == "__future__"
        if _is_docstring(node) or future:
            at = node.end_lineno or node.lineno
        else:
            break
    return at


def _parse(code: str) -> ast.Module | None:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return ast.parse(code)
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        return None
