"""The constitutive tasks' own solution check: the shape of a law, read without running it."""

from pathlib import Path

import pytest
import torch

from sga_agent.parsing import check_candidate
from sga_agent.registry import load_task
from sga_agent.task import CodeRejected
from tasks.constitutive.law_code import LawCodeError, load_law
from tasks.constitutive.law_shape import check_law
from tests.sga_agent.test_parsing import law

LAWS = sorted((Path(__file__).resolve().parents[3] / "examples" / "laws").glob("*.py"))
TASK = load_task("elastic")


@pytest.mark.parametrize("path", LAWS, ids=lambda path: path.stem)
def test_example_laws_pass(path):
    check_candidate(path.read_text(encoding="utf-8"), TASK)


def test_example_laws_are_found():
    assert len(LAWS) >= 5


@pytest.mark.parametrize(
    "code",
    [
        law("return F", head="import math\nimport numpy as np\n"),
        law("return torch.nn.functional.relu(F)"),
        law("return F", init=", *, beta: float = 2.0"),
        law("return getattr(self, 'alpha') * F"),
        law("return F")
        .replace("forward(self, F: torch.Tensor)", "forward(self, input)")
        .replace("return F", "return input"),
        law("return F")
        .replace("(nn.Module)", "(Base)")
        .replace("class Physics", "class Base(torch.nn.Module):\n    pass\n\n\nclass Physics"),
        law() + "\n\nif __name__ == '__main__':\n    print(Physics()(torch.eye(3)))\n",
    ],
    ids=[
        "math-numpy",
        "functional",
        "kw-only-default",
        "literal-getattr",
        "input-argument",
        "local-base",
        "main-guard",
    ],
)
def test_ordinary_laws_pass(code):
    check_candidate(code, TASK)


@pytest.mark.parametrize(
    ("code", "expected"),
    [
        ("import torch\n", "defines no top-level class 'Physics'"),
        (
            "class Physics:\n    def forward(self, F):\n        return F\n",
            "must derive from nn.Module (torch.nn.Module); it derives from nothing",
        ),
        (law().replace("(nn.Module)", "(object)"), "it derives from object"),
        (
            law().replace("self, alpha", "self, beta, alpha"),
            "needs a default value (the starting value of the fit); missing for: beta",
        ),
        (law(init=", *, beta"), "missing for: beta"),
        (
            law().replace("forward(self, F: torch.Tensor)", "forward(self, F, G)"),
            "exactly one required argument besides self, the input F; it requires F, G",
        ),
        (
            law().replace("forward(self, F: torch.Tensor)", "forward(self)"),
            "it requires no argument",
        ),
        (law().replace("def forward", "def backward"), "defines no forward method"),
        (law() + "\n\nclass Physics(nn.Module):\n    pass\n", "is defined twice"),
    ],
    ids=[
        "no-class",
        "no-base",
        "wrong-base",
        "no-default",
        "kw-only",
        "two-inputs",
        "no-input",
        "no-forward",
        "twice",
    ],
)
def test_law_shape_is_checked(code, expected):
    with pytest.raises(CodeRejected) as caught:
        check_law(code)
    assert expected in str(caught.value)


def test_the_task_checks_the_shape_and_the_capture_checks_it_again():
    """The same check, before the capture (feedback by line) and in it (one line)."""
    code = law().replace("self, alpha", "self, beta, alpha").replace("(self, F", "(self, F, G")
    with pytest.raises(CodeRejected) as caught:
        TASK.check_solution(code)
    assert [line for line, _ in caught.value.problems] == [7, 11]
    with pytest.raises(LawCodeError) as refused:
        load_law(code, torch.float64)
    assert str(refused.value) == str(caught.value).replace("\n", "; ")
