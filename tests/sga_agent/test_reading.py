"""Reading answers as a person does: the slips a reader fixes are fixed and named; the rest is
left to the checks."""

from __future__ import annotations

import ast

import pytest

from sga_agent.parsing import check_code
from sga_agent.reading import cut_off_problem, read_answer, template_names

TEMPLATE = """import torch
import torch.nn as nn


class Physics(nn.Module):
    def __init__(self, param: float = 1.0):
        super().__init__()

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        return F
"""
LAW = """class Physics(nn.Module):
    def __init__(self, youngs_modulus: float = 200000, steps: int = 3, nu=0):
        super().__init__()
        self.E = nn.Parameter(torch.tensor(youngs_modulus))
        self.k = nn.Parameter(torch.tensor(1))
        self.steps = steps

    def forward(self, F: torch.Tensor) -> Tuple[torch.Tensor, ...]:
        return F * math.pi * self.E * self.k
"""


def answer(*blocks: str, prose: str = "Here is my answer.") -> str:
    fenced = "\n\n".join(f"```python\n{block}```" for block in blocks)
    return f"{prose}\n\n### Analysis\nIt is too stiff.\n\n### Code\n{fenced}\n"


def test_a_clean_answer_is_read_unchanged():
    law = "import math\n" + TEMPLATE
    reading = read_answer(answer(law), "equation", TEMPLATE)
    assert reading.code == law and reading.fixes == []


def test_missing_imports_integer_defaults_and_typing_names_are_fixed_and_named():
    reading = read_answer(answer(LAW), "equation", TEMPLATE)
    code = reading.code
    assert code is not None
    header = code.splitlines()[:5]
    assert header == [
        "import torch",
        "import torch.nn as nn",
        "import math",
        "from typing import Tuple",
        "class Physics(nn.Module):",
    ]
    assert "youngs_modulus: float = 200000.0" in code and "nu=0.0" in code
    assert "steps: int = 3," in code  # an integer meant as one stays
    assert "torch.tensor(1.0)" in code
    check_code(code, "equation")  # now passes the generic checks
    fixes = " ".join(reading.fixes)
    assert "`import torch`" in fixes and "`from typing import Tuple`" in fixes
    assert "written as floats" in fixes


def test_the_block_defining_the_solution_is_taken_and_a_usage_example_dropped():
    snippet = "x = torch.eye(3)\n"
    law = "import torch\nimport torch.nn as nn\n\n" + TEMPLATE.split("\n\n\n", 1)[1]
    usage_inside = law + (
        "\n\nEPS = 1e-6\nlaw = Physics()\nF = torch.eye(3).expand(4, 3, 3)\nprint(law(F))\n"
        'if __name__ == "__main__":\n    print(law(F).shape)\n'
    )
    usage_after = "law = Physics()\nprint(law(torch.eye(3)[None]))\n"
    reading = read_answer(answer(snippet, usage_inside, usage_after), "equation", TEMPLATE)
    assert reading.code is not None
    assert "print" not in reading.code and "__main__" not in reading.code
    assert "law = Physics()" not in reading.code
    assert "EPS = 1e-6" not in reading.code  # nothing of the law reads it
    ast.parse(reading.code)
    assert reading.fixes[0].startswith("the answer has 3 code blocks; block 2, which defines")
    assert "usage example" in reading.fixes[1]


def test_a_constant_after_the_class_that_the_law_reads_is_kept():
    law = TEMPLATE.replace("return F", "return F * SCALE") + "\n\nSCALE = 2.0\n"
    reading = read_answer(answer(law), "equation", TEMPLATE)
    assert reading.code is not None and "SCALE = 2.0" in reading.code and not reading.fixes


def test_a_cut_off_answer_is_named_as_such_and_a_closed_one_is_not():
    cut = "### Analysis\nLong.\n\n### Code\n```python\nclass Physics(nn.Module):\n    def forw"
    assert read_answer(cut, "equation", TEMPLATE, "length").problem == cut_off_problem()
    assert read_answer("### Analysis\nso much to say", "equation", TEMPLATE, "length").problem
    # cut off in the prose after a complete code block: the code is fine
    done = answer(TEMPLATE) + "\nIn summary, the law"
    assert read_answer(done, "equation", TEMPLATE, "length").code == TEMPLATE
    # an unclosed block without a cut-off (a forgotten fence) is read as it is
    assert read_answer(cut, "equation", TEMPLATE, "stop").code is not None


def test_no_code_is_no_code_and_the_think_part_is_kept_apart():
    reading = read_answer("<think>Maybe a cone.</think>\nI cannot help.", "equation", TEMPLATE)
    assert reading.code is None and "no ```python code block" in reading.problem
    assert reading.reasoning == "Maybe a cone."


def test_a_think_part_whose_opening_tag_the_server_sent_is_kept_apart():
    text = "Maybe a cone.\n```python\nclass Physics: pass\n```\n</think>\n" + answer(TEMPLATE)
    reading = read_answer(text, "equation", TEMPLATE)
    assert reading.code == TEMPLATE and reading.reasoning.startswith("Maybe a cone.")


def test_a_fenced_block_inside_the_think_part_is_not_the_answer():
    text = "<think>\n```python\nclass Physics: pass\n```\n</think>\n" + answer(TEMPLATE)
    reading = read_answer(text, "equation", TEMPLATE)
    assert reading.code == TEMPLATE and "class Physics: pass" in reading.reasoning


def test_entity_code_is_only_chosen_never_edited():
    template = 'smiles = "C"\ncoordinates = [[0.0, 0.0, 0.0]]\n'
    entity = 'smiles = "CO"\ncoordinates = [[0, 0, 0], [1, 0, 0]]\n'
    reading = read_answer(answer("print('hi')\n", entity), "entity", template)
    assert reading.code == entity and not reading.fixes
    assert template_names(template) == {"smiles", "coordinates"}


@pytest.mark.parametrize("broken", ["class Physics(nn.Module:\n    pass\n", "def f(:\n"])
def test_code_that_does_not_parse_is_left_for_the_checks(broken):
    assert read_answer(answer(broken), "equation", TEMPLATE).code == broken


def test_a_trace_of_a_batch_is_read_per_matrix_and_precision_casts_are_dropped():
    law = TEMPLATE.replace(
        "        return F\n",
        "        tr = torch.trace(F @ F.transpose(-2, -1))  # the first invariant, é\n"
        "        s = (F * 2.0).to(torch.float32).double()\n"
        "        return tr * s.float() + F.to(dtype=torch.float64) + F.to(F.device)\n",
    )
    reading = read_answer(answer(law), "equation", TEMPLATE)
    assert reading.code is not None
    assert (
        "tr = torch.diagonal(F @ F.transpose(-2, -1), dim1=-2, dim2=-1).sum(-1)[..., None, None]"
        in reading.code
    )
    assert "s = (F * 2.0)\n" in reading.code
    assert "return tr * s + F + F.to(F.device)" in reading.code
    fixes = " ".join(reading.fixes)
    assert "torch.trace works on one matrix" in fixes and "precision casts" in fixes
    import torch

    namespace: dict = {}
    exec(reading.code, namespace)  # a trusted test of the rewritten code, not a candidate's
    F = torch.eye(3, dtype=torch.float64).expand(4, 3, 3) * 2.0
    out = namespace["Physics"]()(F)
    assert out.shape == (4, 3, 3) and out.dtype == torch.float64
    assert torch.allclose(out[0], 12.0 * 4.0 * torch.eye(3, dtype=torch.float64) + 2 * F[0])
