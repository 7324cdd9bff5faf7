"""Short signatures, checked statically (issue 30: kernels with named arguments).

Every function of the source packages takes at most 12 parameters (``self``/``cls`` not
counted): a longer list is grouped into a struct, an argument pack or a dataclass, so that
adding a constant touches one definition and two values cannot be swapped by position. In
Taichi code (functions decorated ``ti.func`` or ``ti.kernel``) a compile-time argument
(``ti.template()``) is never read by position: no ``a[9]`` or ``a[:9]`` on such a parameter,
and no parameter is unpacked into names (``n, dx, dt = settings``); its members are read by
name.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("taichi_mpm", "bridges", "tasks", "sga_agent", "benchmarks", "scripts", "examples")
MAX_PARAMETERS = 12


def sources() -> list[Path]:
    return sorted(p for package in PACKAGES for p in (ROOT / package).rglob("*.py"))


def functions(path: Path) -> list[ast.FunctionDef | ast.AsyncFunctionDef]:
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    return [n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef)]


def parameters(function: ast.FunctionDef | ast.AsyncFunctionDef) -> list[ast.arg]:
    """Named parameters, without a method's ``self`` or ``cls`` (``*args`` and ``**kwargs``
    are not counted: they name no position)."""
    args = function.args
    named = [*args.posonlyargs, *args.args, *args.kwonlyargs]
    if named and named[0].arg in ("self", "cls"):
        named = named[1:]
    return named


def is_taichi(function: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    """Decorated ``ti.func`` or ``ti.kernel``."""
    return any(ast.unparse(d) in ("ti.func", "ti.kernel") for d in function.decorator_list)


def is_template(arg: ast.arg) -> bool:
    return arg.annotation is not None and ast.unparse(arg.annotation) == "ti.template()"


def positional_reads(function: ast.FunctionDef | ast.AsyncFunctionDef) -> list[str]:
    """Where a Taichi function reads a compile-time argument by position or unpacks an
    argument into names."""
    templates = {a.arg for a in parameters(function) if is_template(a)}
    names = {a.arg for a in parameters(function)}
    found = []
    for node in ast.walk(function):
        if (
            isinstance(node, ast.Subscript)
            and isinstance(node.value, ast.Name)
            and node.value.id in templates
            and (
                isinstance(node.slice, ast.Slice)
                or (isinstance(node.slice, ast.Constant) and isinstance(node.slice.value, int))
            )
        ):
            found.append(f"{ast.unparse(node)} (line {node.lineno})")
        if (
            isinstance(node, ast.Assign)
            and isinstance(node.value, ast.Name)
            and node.value.id in names
            and any(isinstance(t, ast.Tuple | ast.List) for t in node.targets)
        ):
            found.append(f"{ast.unparse(node)} (line {node.lineno})")
    return found


def test_no_function_takes_more_than_twelve_parameters():
    long = [
        f"{path.relative_to(ROOT)}:{f.lineno} {f.name} ({len(parameters(f))} parameters)"
        for path in sources()
        for f in functions(path)
        if len(parameters(f)) > MAX_PARAMETERS
    ]
    assert not long, "group these parameters into a struct, argpack or dataclass:\n" + "\n".join(
        long
    )


def test_taichi_code_reads_arguments_by_name():
    found = [
        f"{path.relative_to(ROOT)} {f.name}: {read}"
        for path in sources()
        for f in functions(path)
        if is_taichi(f)
        for read in positional_reads(f)
    ]
    assert not found, "read these arguments by name:\n" + "\n".join(found)


def test_the_checks_find_what_they_forbid():
    """The checks above on a sample of what they forbid (so that they cannot pass vacuously)."""
    sample = ast.parse(
        "@ti.func\n"
        "def step(s, a: ti.template(), settings):\n"
        "    x = ti.static(a[:9])\n"
        "    y = a[9]\n"
        "    n, dx = settings\n"
        "@ti.func\n"
        "def fine(v, a: ti.template(), p):\n"
        "    return v[0] + a[p, 0] + a.x[p]\n"
        "def long(a, b, c, d, e, f, g, h, i, j, k, l, m):\n"
        "    pass\n"
    )
    step, fine, long = (n for n in sample.body if isinstance(n, ast.FunctionDef))
    assert is_taichi(step) and is_taichi(fine) and not is_taichi(long)
    assert len(positional_reads(step)) == 3
    assert positional_reads(fine) == []
    assert len(parameters(long)) == 13 > MAX_PARAMETERS
