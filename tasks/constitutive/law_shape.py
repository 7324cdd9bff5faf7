"""The shape of a law's code, read from its syntax tree (nothing is run).

A law is one top-level class ``Physics`` deriving from ``torch.nn.Module`` (directly or through
classes of the same file), whose ``__init__`` arguments all have defaults (the starting values
of the fit) and whose ``forward`` takes one input, ``F``. :func:`check_law` is the task's
``check_solution`` (the search runs it before any capture) and :func:`law_problems` is what
:func:`tasks.constitutive.law_code.load_law` checks before it runs a law's code.

Pure standard library: the search process checks laws without importing torch.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator

from sga_agent.task.code import CodeRejected, Problem, dotted_name, import_aliases, parse_python

CLASS_NAME = "Physics"
#: The import that binds each name a law's base class is commonly written with.
_BASE_IMPORTS = {"nn": "import torch.nn as nn", "torch": "import torch",
                 "Module": "from torch.nn import Module"}  # fmt: skip


def check_law(code: str) -> None:
    """Raise :class:`~sga_agent.parsing.CodeRejected` when ``code`` is not shaped as a law."""
    problems = law_problems(parse_python(code))
    if problems:
        raise CodeRejected(problems)


def law_problems(tree: ast.Module) -> list[Problem]:
    """What is wrong with the law's shape, as ``(line, sentence)`` pairs; empty when fine."""
    return list(_problems(tree, import_aliases(tree)))


def _problems(tree: ast.Module, aliases: dict[str, str]) -> Iterator[Problem]:
    """One class ``Physics(nn.Module)``, defaulted ``__init__``, ``forward(self, F)``."""
    classes = {node.name: node for node in tree.body if isinstance(node, ast.ClassDef)}
    found = [node for node in tree.body if isinstance(node, ast.ClassDef)]
    found = [node for node in found if node.name == CLASS_NAME]
    if not found:
        text = f"the code defines no top-level class {CLASS_NAME!r}; define "
        yield 0, text + f"class {CLASS_NAME}(nn.Module) as in the code template"
        return
    if len(found) > 1:
        yield found[1].lineno, f"class {CLASS_NAME} is defined twice; define it exactly once"
        return
    lineage = _lineage(found[0], classes, aliases)
    if lineage is None:
        bases = ", ".join(ast.unparse(base) for base in found[0].bases) or "nothing"
        text = f"class {CLASS_NAME} must derive from nn.Module (torch.nn.Module); it derives"
        yield found[0].lineno, f"{text} from {bases}{_missing_imports(found[0], aliases)}"
        return
    methods = {
        node.name: node
        for klass in reversed(lineage)
        for node in klass.body
        if isinstance(node, ast.FunctionDef)
    }
    missing = _required(methods["__init__"].args) if "__init__" in methods else []
    if missing:
        text = f"every argument of {CLASS_NAME}.__init__ besides self needs a default value"
        text += f" (the starting value of the fit); missing for: {', '.join(missing)}"
        yield methods["__init__"].lineno, text
    if "forward" not in methods:
        text = f"class {CLASS_NAME} defines no forward method; add forward(self, F)"
        yield found[0].lineno, text + " as in the code template"
        return
    required = _required(methods["forward"].args)
    if len(required) != 1 and not (methods["forward"].args.vararg and not required):
        text = f"{CLASS_NAME}.forward must take exactly one required argument besides self,"
        text += f" the input F; it requires {', '.join(required) or 'no argument'}"
        yield methods["forward"].lineno, text


def _missing_imports(cls: ast.ClassDef, aliases: dict[str, str]) -> str:
    """What to import for the template's base class, when the code uses it unimported."""
    roots = []
    for base in cls.bases:
        while isinstance(base, ast.Attribute):
            base = base.value
        if isinstance(base, ast.Name) and base.id in _BASE_IMPORTS and base.id not in aliases:
            roots.append(base.id)
    return "".join(f"; {root} is not imported: add `{_BASE_IMPORTS[root]}`" for root in roots)


def _required(args: ast.arguments) -> list[str]:
    """Names of the arguments without a default value, the first (self) left out."""
    positional = [*args.posonlyargs, *args.args][1:]
    names = [a.arg for a in positional[: len(positional) - len(args.defaults)]]
    return names + [
        a.arg for a, d in zip(args.kwonlyargs, args.kw_defaults, strict=True) if d is None
    ]


def _lineage(
    cls: ast.ClassDef, classes: dict[str, ast.ClassDef], aliases: dict[str, str]
) -> list[ast.ClassDef] | None:
    """``cls`` and its same-file base classes, if one of them derives from nn.Module."""
    seen = [cls]
    while True:
        if any(dotted_name(base, aliases) == "torch.nn.Module" for base in seen[-1].bases):
            return seen
        local = [b.id for b in seen[-1].bases if isinstance(b, ast.Name) and b.id in classes]
        if not local or classes[local[0]] in seen:
            return None
        seen.append(classes[local[0]])
