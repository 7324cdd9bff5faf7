"""Every built-in task, the example plugin of ``examples/numbers_plugin`` and a plugin that
does not subclass ``TaskBase`` keep the plugin contract (:func:`sga_agent.testing.check_task`);
the check itself finds what a plugin gets wrong."""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from sga_agent.registry import load_task, task_names
from sga_agent.task import CodeRejected, Evaluation, PromptParts, TaskBase, as_task, has_hook
from sga_agent.testing import ContractError, check_task
from tests.tasks.observed.conftest import observation_arrays

ROOT = Path(__file__).resolve().parents[1]
BUILT_IN = ["elastic", "plasticine", "granular", "fluid", "imaginary", "homo", "lumo", "gap",
            "gap-low", "observed"]  # fmt: skip


def example_plugin():
    """The documented example plugin's module, loaded from its file (it is not installed)."""
    path = ROOT / "examples" / "numbers_plugin" / "sga_numbers.py"
    spec = importlib.util.spec_from_file_location("sga_numbers", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_built_in_task_is_checked():
    assert set(BUILT_IN) <= set(task_names())


@pytest.mark.parametrize("name", BUILT_IN)
def test_a_built_in_task_keeps_the_contract(name, tmp_path):
    """Statically, the seed captured, the hooks called (scoring runs in the tasks' own
    tests: a fit takes seconds to minutes)."""
    options = {}
    if name == "observed":  # its data is a file named by an option
        np.savez(tmp_path / "observed.npz", **observation_arrays())
        options = {"observation": str(tmp_path / "observed.npz"), "searched": "plastic",
                   "E": 5e4, "nu": 0.3}  # fmt: skip
    check_task(load_task(name), options, evaluate=False)


def test_the_example_plugin_keeps_the_contract_and_scores_its_seed():
    check_task(example_plugin().NumbersTask())


class Plain:
    """A plugin written without ``TaskBase``: what is required, and one hook."""

    name, description, kind = "plain", "Guess zero.", "entity"

    def seed_solution(self) -> str:
        return "0\n"

    def prompt_parts(self) -> PromptParts:
        return PromptParts("a guesser", "guess zero", "x", "one number")

    def check_solution(self, code: str) -> None:
        if not code.strip().lstrip("-").isdigit():
            raise CodeRejected("give one whole number")

    def capture(self, solution: str) -> dict:
        return {"value": solution.strip()}

    def evaluate(self, data, settings) -> Evaluation:
        value = data.get("value") if isinstance(data, dict) else None
        if not isinstance(value, str) or not value.lstrip("-").isdigit():
            return Evaluation.invalid("no number was captured")
        return Evaluation(True, float(int(value)) ** 2, "squared")


def test_a_plugin_that_does_not_subclass_task_base_gets_the_defaults():
    plain = Plain()
    assert not isinstance(plain, TaskBase)
    check_task(plain)
    task = as_task(plain)
    assert task.name == "plain" and task.loss_label == "loss"
    assert task.warm_up_solutions() == [plain.seed_solution()]
    assert task.builtin_proposer() is None  # the defaults
    assert task.assess(None, {}, {}, False) is None
    with pytest.raises(CodeRejected):
        task.check_solution("one")  # its own
    assert has_hook(task, "check_solution") and not has_hook(task, "compare_forms")
    assert has_hook(as_task(load_task("granular")), "compare_forms")  # a subclass's own
    assert not has_hook(as_task(load_task("homo")), "compare_forms")


class Broken(example_plugin().NumbersTask):
    """Wrong in several ways at once."""

    description = None
    loss_lable = "oops"  # misspelt

    def seed_solution(self) -> str:
        return "[0, 0]\n"  # two numbers: its own check refuses it

    def warm_up_solutions(self):
        return "[0, 0, 0]"  # not a list


def test_the_check_lists_every_broken_promise():
    with pytest.raises(ContractError) as raised:
        check_task(Broken())
    text = str(raised.value)
    assert "description must be a str" in text
    assert "'loss_lable' is no hook of the contract; did you mean 'loss_label'?" in text
    assert "the seed fails the static checks: give 3 numbers, not 2" in text
    assert "warm_up_solutions must return a list of str" in text


def test_an_object_without_the_required_members_is_refused():
    with pytest.raises(ContractError, match="lacks .*seed_solution"):
        check_task(object())


@dataclass(frozen=True)
class Lossy:
    """Options a fit worker would get back changed: JSON turns the tuple into a list."""

    sizes: tuple = (1, 2)


class LossyOptions(example_plugin().NumbersTask):
    options_type = Lossy


class MisnamedBuiltinOptions(example_plugin().NumbersTask):
    builtin_options = {"sizez": "3"}


def test_the_check_finds_options_a_fit_worker_would_not_get_back():
    with pytest.raises(ContractError, match="the options must survive JSON unchanged"):
        check_task(LossyOptions(), evaluate=False)
    with pytest.raises(ContractError, match="has no option 'sizez'"):
        check_task(MisnamedBuiltinOptions(), evaluate=False)
