"""Who may import whom (docs/plugin.md, the architecture's table), checked statically.

Every ``import`` and ``from ... import`` of the source files is read with :mod:`ast`, at any
depth (an import inside a function counts as much as one at the top), so that the rules hold
for code paths no test happens to run:

- ``sga_agent`` imports no module of ``tasks``, ``bridges`` or ``taichi_mpm``: it reaches
  tasks only through the registry (entry points);
- ``tasks`` imports of ``sga_agent`` only its protocol package, :mod:`sga_agent.task`
  (which imports nothing beyond the standard library);
- the search core (:mod:`sga_agent.search`) imports no report module, and the report does not
  import the search core;
- ``taichi_mpm`` imports neither torch nor anything of ours; ``bridges`` imports neither
  ``tasks`` nor ``sga_agent``;
- Taichi's private API (``taichi.lang``) is reached by :mod:`taichi_mpm._compat` alone, neither
  imported nor read as an attribute (``ti.lang``) anywhere else in the project's code.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PROTOCOL = "sga_agent.task"  # a package: its modules are the protocol too


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path) -> list[tuple[int, str]]:
    """``(line, module)`` of every import in ``path``; ``from a import b`` gives ``a.b`` (b may
    be a submodule) as well as ``a``; relative imports are resolved."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    package = module_name(path).split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            module = ".".join([*base, *(node.module or "").split(".")]).strip(".")
            found.append((node.lineno, module))
            found += [(node.lineno, f"{module}.{alias.name}") for alias in node.names]
    return found


def sources(package: str) -> list[Path]:
    return sorted((ROOT / package).rglob("*.py"))


def within(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


def offences(package: str, forbidden) -> list[str]:
    """``file:line imports module`` for each import of ``package``'s files that ``forbidden``
    (module name, importing module name) flags."""
    found = {}
    for path in sources(package):
        importer = module_name(path)
        for line, module in imports(path):
            where = f"{path.relative_to(ROOT)}:{line}"
            if forbidden(module, importer) and where not in found:  # the module, not its names
                found[where] = f"{where} imports {module}"
    return sorted(found.values())


def test_the_agent_imports_no_task_bridge_or_simulator():
    def forbidden(module: str, importer: str) -> bool:
        return any(within(module, p) for p in ("tasks", "bridges", "taichi_mpm"))

    assert offences("sga_agent", forbidden) == []


def test_tasks_import_only_the_protocol_module_of_the_agent():
    def forbidden(module: str, importer: str) -> bool:
        # ``from sga_agent.task import X`` also yields ``sga_agent.task.X``: allowed
        return (
            within(module, "sga_agent") and module != "sga_agent" and not within(module, PROTOCOL)
        )

    assert offences("tasks", forbidden) == []


def test_the_search_core_and_the_report_do_not_import_each_other():
    def forbidden(module: str, importer: str) -> bool:
        if importer == "sga_agent.search":
            return within(module, "sga_agent.report")
        if within(importer, "sga_agent.report"):
            return within(module, "sga_agent.search") or within(module, "sga_agent.runner")
        return False

    assert offences("sga_agent", forbidden) == []


def test_the_simulator_and_the_bridges_stand_alone():
    def simulator(module: str, importer: str) -> bool:
        return any(within(module, p) for p in ("torch", "bridges", "tasks", "sga_agent"))

    def bridge(module: str, importer: str) -> bool:
        return any(within(module, p) for p in ("tasks", "sga_agent"))

    assert offences("taichi_mpm", simulator) == []
    assert offences("bridges", bridge) == []


def test_the_protocol_package_imports_only_the_standard_library():
    """A task package imports it; it must not drag the agent (litellm, rich) along."""
    import sys

    for path in sorted((ROOT / "sga_agent" / "task").glob("*.py")):
        outside = {
            module for _, module in imports(path)
            if not within(module, PROTOCOL) and module.split(".")[0] != "__future__"
        }  # fmt: skip
        assert {module.split(".")[0] for module in outside} <= set(sys.stdlib_module_names), path


#: The project's code (the tests may reach anywhere).
CODE = ("taichi_mpm", "bridges", "tasks", "sga_agent", "benchmarks", "scripts", "examples")
COMPAT = "taichi_mpm._compat"


def taichi_internals(path: Path) -> list[int]:
    """Lines of ``path`` that import ``taichi.lang`` or read it as ``ti.lang``/``taichi.lang``."""
    lines = [line for line, module in imports(path) if within(module, "taichi.lang")]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        names_taichi = isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
        if names_taichi and node.value.id in ("ti", "taichi") and node.attr == "lang":
            lines.append(node.lineno)
    return lines


def test_only_the_compat_module_reaches_into_taichi_s_internals():
    found = [f"{path.relative_to(ROOT)}:{line}" for package in CODE for path in sources(package)
             if module_name(path) != COMPAT for line in taichi_internals(path)]  # fmt: skip
    assert found == []
    assert taichi_internals(ROOT / "taichi_mpm" / "_compat.py")  # the check sees what it looks for


@pytest.mark.parametrize("package", ["sga_agent", "tasks", "taichi_mpm", "bridges"])
def test_the_check_reads_every_file(package):
    """A check that reads no file passes vacuously: make sure it reads some."""
    assert len(sources(package)) > 10
    assert any(imports(path) for path in sources(package))
