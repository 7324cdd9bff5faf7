"""Reading a model's answer, and checking its code before anything runs it.

:func:`parse_response` splits an answer into its sections ("### Analysis", "### Step-by-Step
Plan", "### Code") and its python code blocks (:mod:`sga_agent.reading` chooses the
solution's). :func:`check_code` inspects that code through its syntax tree only (nothing is
executed) and raises :class:`CodeRejected`, whose message is feedback for the next prompt,
when it breaks a generic safety rule:

- imports only from the allowed top-level modules (torch, math and numpy for equation tasks,
  with the harmless standard modules of :data:`HARMLESS_IMPORTS` such as ``typing``; none
  for entity tasks), never from :data:`FORBIDDEN_MODULES`;
- no builtins that run code, touch files or inspect the interpreter (:data:`FORBIDDEN_NAMES`),
  and ``getattr``/``setattr``/``delattr``/``hasattr`` only with a literal attribute name;
- no dunder attributes besides ``__init__``, no private attributes of imported modules, and no
  attribute that loads, saves or compiles code or data (:data:`FORBIDDEN_ATTRIBUTES`), nor one
  named like a forbidden module (``torch.os``).

The shape a solution must have (a ``Physics`` module, a molecule's literals, ...) is the task's
business: its ``check_solution(code)`` (see :class:`sga_agent.task.TaskBase`) raises
:class:`CodeRejected` too.
:func:`check_candidate` runs both, as the search and ``sga-agent evaluate`` do, and reports
their problems together.

These checks give fast, readable feedback and stop obvious hostility; they are not the
security boundary, which is the sandboxed worker that evaluates a candidate.
"""

from __future__ import annotations

import ast
import re
import textwrap
from collections.abc import Collection, Iterator
from dataclasses import dataclass

from sga_agent.task import Task, as_task
from sga_agent.task.code import (
    CodeRejected,
    Problem,
    bound_names,
    dotted_name,
    import_aliases,
    parse_python,
)

#: Standard-library modules of no harm that models import out of habit (type hints, small
#: helpers), allowed beside a kind's own; the capture process has them loaded already.
HARMLESS_IMPORTS = (
    "__future__", "abc", "collections", "dataclasses", "enum", "functools", "itertools",
    "numbers", "typing",
)  # fmt: skip
#: Imports allowed by default, per task kind (top-level module names).
DEFAULT_IMPORTS: dict[str, tuple[str, ...]] = {
    "equation": ("torch", "math", "numpy", *HARMLESS_IMPORTS),
    "entity": (),
}
#: Modules that reach files, processes, the network or the interpreter's machinery. Never
#: importable, and never reachable as an attribute (``torch.os``).
FORBIDDEN_MODULES = frozenset({
    "builtins", "code", "codeop", "concurrent", "ctypes", "dbm", "gc", "glob", "http",
    "importlib", "inspect", "io", "marshal", "mmap", "multiprocessing", "os", "pathlib",
    "pickle", "platform", "posix", "pty", "requests", "runpy", "shelve", "shutil", "signal",
    "site", "socket", "subprocess", "sys", "sysconfig", "tempfile", "threading", "urllib",
    "webbrowser", "zipfile", "_thread",
})  # fmt: skip
#: Attributes (of any object) that load, save, download or compile code or data:
#: ``torch.hub``, ``torch.load``/``save``, ``torch.jit``, ``torch.compile``,
#: ``torch.utils.cpp_extension``, ``torch.ops``/``classes``/``library``/``_C``,
#: ``numpy.load``/``save``/``fromfile``/``ndarray.tofile`` and relatives.
FORBIDDEN_ATTRIBUTES = frozenset({
    "_C", "DataSource", "classes", "compile", "cpp_extension", "ctypeslib", "distributed",
    "distutils", "dump", "f2py", "from_file", "fromfile", "fromregex", "genfromtxt", "hub",
    "jit", "library", "load", "loadtxt", "memmap", "open_memmap", "ops", "package",
    "recfromcsv", "recfromtxt", "save", "savetxt", "savez", "savez_compressed",
    "serialization", "tensorboard", "tofile",
})  # fmt: skip
#: Builtins that run code, touch files or expose the interpreter; rejected wherever they occur.
FORBIDDEN_NAMES = frozenset({
    "__import__", "breakpoint", "compile", "eval", "exec", "globals", "locals", "open", "vars",
})  # fmt: skip
#: Builtins for an interactive session; rejected unless the code binds the name itself (a
#: ``forward(self, input)`` argument is fine).
INTERACTIVE_NAMES = frozenset({"copyright", "credits", "exit", "help", "input", "license", "quit"})
_ATTRIBUTE_FUNCTIONS = frozenset({"delattr", "getattr", "hasattr", "setattr"})
_ALLOWED_DUNDERS = frozenset({"__init__"})
_CODE_TAGS = frozenset({"", "python", "python3", "py"})
_SECTIONS = {"analysis": "analysis", "step-by-step plan": "plan", "step by step plan": "plan",
             "plan": "plan", "code": "code"}  # fmt: skip
_HEADING = re.compile(r"^ {0,3}#{1,6}\s+(?:\d+[.)]\s*)?(.*?)[\s#]*$")  # "## 2. Plan" too


@dataclass(frozen=True)
class ParsedResponse:
    """A model's answer, split up.

    Parameters
    ----------
    sections : dict of str to str
        Text of the "### Analysis", "### Step-by-Step Plan" and "### Code" sections, under the
        keys "analysis", "plan" and "code", for those present (the last one wins if repeated).
    code : str or None
        The last python (or untagged) fenced code block; None when the answer has none.
    blocks : tuple of str
        Every python (or untagged) fenced code block, in order.
    open_block : bool
        The last code block is never closed: the answer ends inside it (cut off, or the
        fence was forgotten).
    """

    sections: dict[str, str]
    code: str | None
    blocks: tuple[str, ...] = ()
    open_block: bool = False


def parse_response(text: str) -> ParsedResponse:
    """Split a model's answer into its sections and its last python code block.

    Headings inside code blocks do not count; a code block left open at the end of the answer
    (a truncated answer) runs to the end.
    """
    lines = text.splitlines()
    headings: list[tuple[int, str]] = []
    fences = list(_fences(lines))
    blocks = tuple(  # a block indented in a list item loses its common indentation
        textwrap.dedent("\n".join(lines[start:stop])).strip("\n") + "\n"
        for start, stop, tag in fences
        if tag in _CODE_TAGS
    )
    code_fences = [stop for _, stop, tag in fences if tag in _CODE_TAGS]
    open_block = bool(code_fences) and code_fences[-1] >= len(lines)
    inside = {i for start, stop, _ in fences for i in range(start - 1, stop + 1)}
    for i, line in enumerate(lines):
        match = _HEADING.match(line)
        if i not in inside and match:
            key = _SECTIONS.get(match.group(1).strip("*_: ").lower())
            if key:
                headings.append((i, key))
    sections = {}
    bounds = [i for i, _ in headings] + [len(lines)]
    for (i, key), end in zip(headings, bounds[1:], strict=True):
        sections[key] = "\n".join(lines[i + 1 : end]).strip()
    code = blocks[-1] if blocks else None
    return ParsedResponse(sections=sections, code=code, blocks=blocks, open_block=open_block)


def _fences(lines: list[str]) -> Iterator[tuple[int, int, str]]:
    """``(first, end, tag)`` of each fenced block: body lines ``first:end``, lowercase tag."""
    i = 0
    while i < len(lines):
        opening = lines[i].lstrip(" ")
        if opening.startswith("```") and len(lines[i]) - len(opening) <= 3:
            ticks = len(opening) - len(opening.lstrip("`"))
            words = opening[ticks:].split()
            end = i + 1
            while end < len(lines) and not _closes(lines[end], ticks):
                end += 1
            yield i + 1, end, words[0].lower() if words else ""
            i = end
        i += 1


def _closes(line: str, ticks: int) -> bool:
    stripped = line.strip()
    return len(stripped) >= ticks and set(stripped) == {"`"}


def check_candidate(code: str, task: Task) -> None:
    """Check a solution for ``task`` statically: the generic rules of :func:`check_code`, then
    the task's own ``check_solution(code)`` (code that does not parse is not shown to it).

    Raises
    ------
    CodeRejected
        The problems of both checks together, listed by line.
    """
    problems = _problems(code, task.kind, None)
    try:
        as_task(task).check_solution(code)
    except CodeRejected as error:
        problems += error.problems
    if problems:
        raise CodeRejected(problems)


def check_code(code: str, kind: str, allowed_imports: Collection[str] | None = None) -> None:
    """Check a solution's code against the generic rules, statically, without running it.

    Parameters
    ----------
    code : str
        The code block of an answer.
    kind : str
        The task kind, ``"equation"`` or ``"entity"``: picks the default imports.
    allowed_imports : collection of str, optional
        Top-level modules the code may import; default :data:`DEFAULT_IMPORTS` of ``kind``.
        :data:`FORBIDDEN_MODULES` stay forbidden even when listed.

    Raises
    ------
    CodeRejected
        The code breaks a rule; the message lists up to five problems, one sentence each,
        prefixed with the line number where there is one.
    ValueError
        ``kind`` is unknown.
    """
    problems = _problems(code, kind, allowed_imports)
    if problems:
        raise CodeRejected(problems)


def _problems(code: str, kind: str, allowed_imports: Collection[str] | None) -> list[Problem]:
    """What :func:`check_code` reports; raises :class:`CodeRejected` for invalid syntax."""
    if kind not in DEFAULT_IMPORTS:
        raise ValueError(f"kind must be one of {tuple(DEFAULT_IMPORTS)}, got {kind!r}")
    allowed = DEFAULT_IMPORTS[kind] if allowed_imports is None else tuple(allowed_imports)
    tree = parse_python(code)
    checker = _Checker(tree, allowed)
    checker.visit(tree)
    return checker.problems


def _listing(names: Collection[str]) -> str:
    names = list(names)
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def _dunder(name: str) -> bool:
    return len(name) > 4 and name.startswith("__") and name.endswith("__")


def _attribute_ok(name: str) -> bool:
    return not (
        (_dunder(name) and name not in _ALLOWED_DUNDERS)
        or name in FORBIDDEN_ATTRIBUTES
        or name in FORBIDDEN_MODULES
    )


class _Checker(ast.NodeVisitor):
    """Collects ``(line, sentence)`` problems of imports, names and attributes."""

    def __init__(self, tree: ast.Module, allowed: tuple[str, ...]) -> None:
        self.allowed = allowed
        self.problems: list[Problem] = []
        self.aliases = import_aliases(tree)
        self.bound = bound_names(tree)

    def reject(self, node: ast.AST, text: str) -> None:
        self.problems.append((getattr(node, "lineno", 0), text))

    def _imports_hint(self) -> str:
        if not self.allowed:
            return "this task's code may not import anything"
        own = [name for name in self.allowed if name not in HARMLESS_IMPORTS]
        if len(own) < len(self.allowed):
            return f"only {', '.join(own)} and standard helpers such as typing may be imported"
        return f"only {_listing(self.allowed)} may be imported"

    def _check_module(self, node: ast.AST, dotted: str) -> bool:
        parts = dotted.split(".")
        if parts[0] in FORBIDDEN_MODULES:
            self.reject(
                node,
                f"importing {parts[0]!r} is not allowed: solutions may not reach "
                f"files, processes or the network; {self._imports_hint()}",
            )
        elif parts[0] not in self.allowed:
            self.reject(node, f"importing {parts[0]!r} is not allowed; {self._imports_hint()}")
        else:
            return self._check_path(node, parts)
        return False

    def _check_path(self, node: ast.AST, parts: list[str]) -> bool:
        """Reject a forbidden or private part of an imported module path; True when fine."""
        for part in parts[1:]:
            if (part.startswith("_") and not _dunder(part)) or not _attribute_ok(part):
                self.reject(node, f"{'.'.join(parts)!r} is not allowed; " + _why(part))
                return False
        return True

    def visit_Import(self, node: ast.Import) -> None:
        for alias in node.names:
            self._check_module(node, alias.name)

    def visit_ImportFrom(self, node: ast.ImportFrom) -> None:
        if node.level:
            self.reject(node, f"relative imports are not allowed; {self._imports_hint()}")
        elif self._check_module(node, node.module or ""):
            for alias in node.names:
                if alias.name == "*":
                    self.reject(
                        node,
                        f"'from {node.module} import *' is not allowed; import "
                        "the names you use explicitly",
                    )
                else:
                    self._check_path(node, [*(node.module or "").split("."), alias.name])

    def visit_Name(self, node: ast.Name) -> None:
        name = node.id
        if name in FORBIDDEN_NAMES:
            self.reject(node, f"{name!r} is not allowed: " + _why(name))
        elif name in INTERACTIVE_NAMES and name not in self.bound:
            self.reject(
                node,
                f"{name!r} is not allowed: a solution runs without a terminal or a user to talk to",
            )
        elif name in _ATTRIBUTE_FUNCTIONS:
            self.reject(
                node,
                f"{name!r} may only be called directly, with a literal attribute "
                f'name: {name}(obj, "name", ...)',
            )
        elif _dunder(name) and name != "__name__":
            self.reject(
                node,
                f"the name {name!r} is not allowed; dunder names reach the interpreter's internals",
            )

    def visit_Attribute(self, node: ast.Attribute) -> None:
        private = node.attr.startswith("_") and dotted_name(node, self.aliases) is not None
        if not _attribute_ok(node.attr) or private:
            self.reject(node, f"{_source(node)!r} is not allowed; " + _why(node.attr))
        else:
            self.generic_visit(node)

    def visit_Call(self, node: ast.Call) -> None:
        func = node.func
        if isinstance(func, ast.Name) and func.id in _ATTRIBUTE_FUNCTIONS:
            name = node.args[1] if len(node.args) > 1 else None
            if not (isinstance(name, ast.Constant) and isinstance(name.value, str)):
                self.reject(
                    node,
                    f"{func.id}() needs a plain string literal as the attribute "
                    f'name, e.g. {func.id}(self, "alpha", ...); better use '
                    "self.alpha",
                )
            elif not _attribute_ok(name.value) and func.id != "hasattr":
                self.reject(node, f"accessing {name.value!r} is not allowed; " + _why(name.value))
            for child in [*node.args, *node.keywords]:
                self.visit(child)
        else:
            self.generic_visit(node)


def _why(name: str) -> str:
    if name in FORBIDDEN_MODULES:
        return "solutions may not reach files, processes or the network"
    if name in FORBIDDEN_NAMES:
        return "solutions may not run generated code, open files or inspect the interpreter"
    if _dunder(name):
        return "no dunder attribute other than __init__ may be used"
    if name.startswith("_"):
        return "use the public API of the module"
    return "solutions may not load, save, download or compile code or data"


def _source(node: ast.expr) -> str:
    """The code of ``node`` as written, or ``.attr`` when that is long."""
    text = ast.unparse(node)
    return text if len(text) <= 60 or not isinstance(node, ast.Attribute) else "." + node.attr
