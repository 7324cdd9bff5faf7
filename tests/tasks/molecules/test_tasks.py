"""The four molecule tasks as registered plugins."""

from __future__ import annotations

import sys

import pytest

from sga_agent.registry import load_task
from sga_agent.task import EvaluationSettings, PromptParts, Task
from tasks.molecules import GapLowTask, GapTask, HomoTask, LumoTask
from tasks.molecules.solution import parse_solution
from tasks.molecules.validation import check_proposal
from tests.tasks.molecules.helpers import score

TASKS = {"homo": (HomoTask, "homo", 0.0), "lumo": (LumoTask, "lumo", 0.0)}
TASKS |= {"gap": (GapTask, "gap", 0.0), "gap-low": (GapLowTask, "gap", -2.0)}


@pytest.mark.parametrize("name", sorted(TASKS))
def test_registered_task_satisfies_the_protocol(name: str) -> None:
    cls, prop, target = TASKS[name]
    task = load_task(name)
    assert isinstance(task, cls) and isinstance(task, Task)
    assert task.name == name and task.kind == "entity"
    assert task.prop == prop and task.target == target
    assert task.description and "\n" not in task.description
    parts = task.prompt_parts()
    assert isinstance(parts, PromptParts)
    assert all(isinstance(p, str) and p.strip() for p in vars(parts).values())
    assert "SMILES" in parts.template and "coordinates" in parts.template
    assert f"reaches {target:g} " in parts.context


def test_seed_solution_is_a_valid_molecule() -> None:
    seed = HomoTask().seed_solution()
    checked = check_proposal(parse_solution(seed))
    assert checked.n_heavy >= 8
    assert all(t().seed_solution() == seed for t in (LumoTask, GapTask, GapLowTask))


def test_seed_solution_evaluates() -> None:
    evaluation = score(GapTask(), GapTask().seed_solution(), EvaluationSettings(epochs=2))
    assert evaluation.valid, evaluation.reason
    assert evaluation.extras["geometry_source"] == "proposal"
    assert evaluation.loss < 10


def test_capture_passes_the_text_on_and_the_fit_checks_it() -> None:
    """The capture runs nothing (the text is data); the fit refuses data that is not text."""
    seed = HomoTask().seed_solution()
    assert HomoTask().capture(seed) == {"solution": seed}
    assert HomoTask().capture("import os; os._exit(1)") == {"solution": "import os; os._exit(1)"}
    for data in (None, {}, {"solution": 3}, {"law": seed}):
        evaluation = HomoTask().evaluate(data, EvaluationSettings(epochs=0))
        assert not evaluation.valid and evaluation.status == "error"
        assert evaluation.reason == "the captured solution is not text"


def test_importing_the_package_is_light() -> None:
    """Listing tasks must not pay for torch, RDKit or dxtb (checked in a fresh interpreter)."""
    import subprocess

    code = (
        "import sys, tasks.molecules as m; m.HomoTask().prompt_parts(); "
        "print(sorted(x for x in ('torch', 'rdkit', 'dxtb') if x in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
