"""A law whose code fails while it is loaded, built or captured is refused with one line that
names the cause, the law's line (quoted) and the fix: one small failing law per row of the
hint table, captured here in the test process (torch only, nothing is simulated)."""

from __future__ import annotations

import re
from dataclasses import dataclass

import pytest

from sga_agent.helper_protocol import MAX_MESSAGE_CHARS
from tasks.constitutive.law_capture import capture_law
from tasks.constitutive.law_code import LawCodeError
from tasks.constitutive.law_errors import HINTS, find_hint, quote_line

#: Longest refusal, in characters (one line for the model; the prompt's failure section keeps
#: this many of a reason, see sga_agent.failures.MAX_REASON_CHARS).
MAX_CHARS = 420


def law(forward: str, init: str = "", arguments: str = "", head: str = "") -> str:
    """A law with ``forward``'s body (and ``__init__``'s after super().__init__())."""
    indent = "        "
    body = "".join(indent + line + "\n" for line in forward.strip("\n").splitlines())
    setup = "".join(indent + line + "\n" for line in init.strip("\n").splitlines())
    return (
        f"import torch\nimport torch.nn as nn\n{head}\n\nclass Physics(nn.Module):\n"
        f"    def __init__(self{arguments}):\n        super().__init__()\n{setup}"
        f"        self.scale = nn.Parameter(torch.tensor(1.0))\n\n"
        f"    def forward(self, F):\n{body}"
    )


@dataclass(frozen=True)
class Case:
    """A failing law, the line that fails (stripped), and phrases the refusal must contain:
    its cause and its fix."""

    code: str
    line: str
    cause: str
    fix: str


CASES = {
    "torch.trace of a batch": Case(
        law("tr = torch.trace(F)\nreturn F * tr"),
        "tr = torch.trace(F)",
        "torch.trace works on one matrix",
        "use torch.diagonal(A, dim1=-2, dim2=-1).sum(-1)",
    ),
    "integer parameter": Case(
        law("return F * self.k", init="self.k = nn.Parameter(torch.tensor(2))"),
        "self.k = nn.Parameter(torch.tensor(2))",
        "a parameter was built from an integer tensor",
        "write its default as a float, 1.0 not 1",
    ),
    "float32 meets float64": Case(
        law("eye = torch.eye(3, dtype=torch.float32).expand_as(F)\nreturn torch.bmm(F, eye)"),
        "return torch.bmm(F, eye)",
        "float32 and float64 tensors meet in one operation",
        "create tensors with dtype=F.dtype, or torch.eye(3, dtype=F.dtype)",
    ),
    "if on a batch": Case(
        law("J = torch.det(F)\nif J < 1:\n    return F\nreturn F * self.scale"),
        "if J < 1:",
        "has no single truth value",
        "torch.where(condition, a, b) instead of an if",
    ),
    "if on a parameter": Case(
        law("if self.scale > 0:\n    return F * self.scale\nreturn F"),
        "if self.scale > 0:",
        "reads a tensor's value",
        "use torch.where(condition, a, b) instead of an if",
    ),
    ".item()": Case(
        law("s = self.scale.item()\nreturn F * s"),
        "s = self.scale.item()",
        "reads a tensor's value",
        "use torch.where(condition, a, b) instead of an if",
    ),
    "float() of a tensor": Case(
        law("J = float(torch.det(F).mean())\nreturn F * J"),
        "J = float(torch.det(F).mean())",
        "reads a tensor's value",
        "keep every value a tensor",
    ),
    ".numpy()": Case(
        law("twice = F.detach().numpy() * 2.0\nreturn torch.from_numpy(twice) * self.scale"),
        "twice = F.detach().numpy() * 2.0",
        "converts a tensor to NumPy",
        "use torch operations on tensors only",
    ),
    "det of a slice": Case(
        law("J = torch.det(F[:, :2])\nreturn F * J.view(-1, 1, 1)"),
        "J = torch.det(F[:, :2])",
        "need square matrices",
        "pass (B, 3, 3) matrices",
    ),
    "inverse of a slice": Case(
        law("return torch.linalg.inv(F[:, :, :2])"),
        "return torch.linalg.inv(F[:, :, :2])",
        "need square matrices",
        "F is (B, 3, 3)",
    ),
    "broadcast": Case(
        law("return F + F[:, :2]"),
        "return F + F[:, :2]",
        "the shapes of two tensors do not fit together",
        "F is (B, 3, 3): a value per particle is (B, 1, 1)",
    ),
    "matrix product": Case(
        law("return F @ F[:, :2]"),
        "return F @ F[:, :2]",
        "the shapes of two tensors do not fit together",
        "A @ B needs (B, n, k) @ (B, k, m)",
    ),
    "dim out of range": Case(
        law("return F * F.sum(dim=3)"),
        "return F * F.sum(dim=3)",
        "a dim argument is beyond the tensor's dimensions",
        "its dims are 0 (particles), 1 and 2",
    ),
    ".view of a transpose": Case(
        law("return F.transpose(1, 2).view(-1, 9).view(-1, 3, 3)"),
        "return F.transpose(1, 2).view(-1, 9).view(-1, 3, 3)",
        ".view needs contiguous memory",
        "use .reshape(...) instead of .view(...)",
    ),
    "torch.tensor of tensors": Case(
        law("J = torch.det(F)\nv = torch.tensor([J, J])\nreturn F * v.sum()"),
        "v = torch.tensor([J, J])",
        "a tensor of many values is used as one number",
        "torch.stack([a, b], dim=-1)",
    ),
    "math of a tensor": Case(
        law("return F * math.exp(torch.det(F))", head="import math"),
        "return F * math.exp(torch.det(F))",
        "a tensor of many values is used as one number",
        "torch.exp replaces math.exp",
    ),
    "svd with some=": Case(
        law("U, S, V = torch.linalg.svd(F, some=True)\nreturn U @ V"),
        "U, S, V = torch.linalg.svd(F, some=True)",
        "torch.svd takes some=, torch.linalg.svd full_matrices=",
        "write U, S, Vh = torch.linalg.svd(F)",
    ),
    "svd's V": Case(
        law("V = torch.linalg.svd(F).V\nreturn V"),
        "V = torch.linalg.svd(F).V",
        "the result of torch.linalg.svd has the fields U, S and Vh",
        "V is Vh.transpose(-2, -1)",
    ),
    "svd unpacked in two": Case(
        law("U, S = torch.linalg.svd(F)\nreturn U"),
        "U, S = torch.linalg.svd(F)",
        "the names on the left of = are not as many as the values returned",
        "torch.linalg.svd returns U, S, Vh",
    ),
    "misspelt torch function": Case(
        law("return torch.matmull(F, F)"),
        "return torch.matmull(F, F)",
        "torch.matmull does not exist",
        "did you mean torch.matmul",
    ),
    "torch.linalg.trace": Case(
        law("return F * torch.linalg.trace(F).view(-1, 1, 1)"),
        "return F * torch.linalg.trace(F).view(-1, 1, 1)",
        "torch.linalg.trace does not exist",
        "for a batch use torch.diagonal(A, dim1=-2, dim2=-1).sum(-1)",
    ),
    "torch.linalg.exp": Case(
        law("return torch.linalg.exp(F)"),
        "return torch.linalg.exp(F)",
        "torch.linalg.exp does not exist",
        "it exists as torch.exp",
    ),
    "misspelt tensor method": Case(
        law("return F.transpoze(1, 2)"),
        "return F.transpoze(1, 2)",
        "tensors have no method .transpoze",
        "did you mean .transpose",
    ),
    "method of a float": Case(
        law("k = 2.0\nreturn F * k.exp()"),
        "return F * k.exp()",
        "a Python float has no method .exp",
        "torch.as_tensor(x, dtype=F.dtype)",
    ),
    "parameter without self": Case(
        law(
            "return F * mu",
            init="self.mu = nn.Parameter(torch.tensor(mu))",
            arguments=", mu: float = 1.0",
        ),  # fmt: skip
        "return F * mu",
        "the name mu is not defined where it is used",
        "mu is an attribute of the law: write self.mu",
    ),
    "misspelt name": Case(
        law("strain = F - torch.eye(3, dtype=F.dtype)\nreturn F + strian"),
        "return F + strian",
        "the name strian is not defined where it is used",
        "did you mean strain?",
    ),
    "missing import": Case(
        law("return F", init="self.k = nn.Parameter(torch.tensor(math.log(2.0)))"),
        "self.k = nn.Parameter(torch.tensor(math.log(2.0)))",
        "the name math is not defined where it is used",
        "add `import math` at the top of the code",
    ),
    "parameter before super().__init__()": Case(
        "import torch\nimport torch.nn as nn\n\n\nclass Physics(nn.Module):\n"
        "    def __init__(self, k: float = 1.0):\n"
        "        self.k = nn.Parameter(torch.tensor(k))\n        super().__init__()\n\n"
        "    def forward(self, F):\n        return F * self.k\n",
        "self.k = nn.Parameter(torch.tensor(k))",
        "before nn.Module is initialized",
        "call super().__init__() first in __init__",
    ),
    "a float where a tensor is needed": Case(
        law("return F * torch.exp(0.5)"),
        "return F * torch.exp(0.5)",
        "a torch function got a Python float where it needs a tensor",
        "use math for plain numbers",
    ),
    "arguments torch.eye does not take": Case(
        law("return F @ torch.eye(3, 3, 3, dtype=F.dtype)"),
        "return F @ torch.eye(3, 3, 3, dtype=F.dtype)",
        "a torch function was called with arguments it does not take",
        "torch.eye(3, dtype=F.dtype).expand_as(F)",
    ),
}


def refusal(code: str) -> str:
    with pytest.raises(LawCodeError) as refused:
        capture_law(code)
    return str(refused.value)


def line_number(code: str, line: str) -> int:
    numbers = [n for n, text in enumerate(code.splitlines(), 1) if text.strip() == line]
    assert len(numbers) == 1, line
    return numbers[0]


@pytest.mark.parametrize("name", list(CASES))
def test_a_failing_law_is_refused_with_its_line_cause_and_fix(name):
    """Cause, then line, then fix, then torch's message: a reason cut to the capture server's
    length keeps all but the last."""
    case = CASES[name]
    message = refusal(case.code)
    assert "\n" not in message and len(message) <= MAX_CHARS, message
    assert message.endswith(".") and "?." not in message, message
    where = f"At line {line_number(case.code, case.line)} (`{case.line}`). Fix: "
    cause, _, fix = message.partition(where)
    assert case.cause in cause and case.fix in fix, message
    assert len(message.split(". Raised ")[0]) <= MAX_MESSAGE_CHARS, message


def test_every_hint_has_a_failing_law():
    """Each row of the table is reached by one of the laws above (by its cause: a part of the
    row's, or the row's with its blanks filled)."""
    causes = [case.cause for case in CASES.values()]
    for hint in HINTS:
        filled = re.sub(r"\\\{\w+\\\}", r"\\S+", re.escape(hint.cause))
        assert any(cause in hint.cause or re.search(filled, cause) for cause in causes), hint


def test_hints_are_found_by_their_message():
    found = find_hint("RuntimeError: trace: expected a matrix, but got tensor with dim 3")
    assert found is not None and "torch.diagonal" in found[0].fix
    found = find_hint("NameError: name 'nn' is not defined")
    assert found is not None and found[1]["name"] == "nn"
    assert find_hint("RuntimeError: something no row knows") is None


def test_an_integer_default_gets_the_float_hint():
    """``E: float = 1000`` used as nn.Parameter(torch.tensor(E)) is an integer tensor."""
    code = law(
        "return F * self.E",
        init="self.E = nn.Parameter(torch.tensor(E))",
        arguments=", E: float = 1000, nu: float = 0.3",
    )
    message = refusal(code)
    line = line_number(code, "self.E = nn.Parameter(torch.tensor(E))")
    assert message.startswith("Physics() failed: a parameter was built from an integer")
    assert f"At line {line} (`self.E = nn.Parameter(torch.tensor(E))`). Fix: " in message
    assert "Fix: write its default as a float, 1.0 not 1 (E=1000 -> E=1000.0). Raised " in message


def test_an_unknown_error_still_names_its_line():
    code = law('raise ValueError("no law yet")')
    message = refusal(code)
    line = line_number(code, 'raise ValueError("no law yet")')
    assert message == (
        f"the law could not be captured: ValueError: no law yet, at line {line} "
        '(`raise ValueError("no law yet")`)'
    )


def test_an_error_in_a_helper_names_the_helper_line():
    code = law("return F * trace(F).view(-1, 1, 1)", head="\n\ndef trace(A):\n    return "
               "torch.trace(A)\n")  # fmt: skip
    message = refusal(code)
    assert f"At line {line_number(code, 'return torch.trace(A)')} (`return" in message


def test_an_error_while_the_code_runs_names_its_line():
    """A name undefined at the top level fails when the code is run, before Physics()."""
    code = law("return F * SCALE", head="SCALE = math.pi")
    message = refusal(code)
    assert message.startswith("running the code failed: the name math is not defined")
    assert f"At line {line_number(code, 'SCALE = math.pi')} (`SCALE = math.pi`)" in message
    assert "Fix: add `import math` at the top of the code" in message


def test_a_syntax_error_quotes_its_line():
    message = refusal("import torch\nclass Physics(nn.Module:\n    pass\n")
    assert message.startswith("the code does not compile: SyntaxError:")
    assert message.endswith("at line 2 (`class Physics(nn.Module:`)")


def test_a_refused_operation_names_its_line():
    code = law("noise = torch.rand_like(F)\nreturn F + 1e-3 * noise")
    message = refusal(code)
    assert "aten.rand_like" in message and "not allowed" in message
    assert message.endswith(f"At line {line_number(code, 'noise = torch.rand_like(F)')} "
                            "(`noise = torch.rand_like(F)`)")  # fmt: skip


def test_nn_unimported_in_the_class_line_names_the_import():
    code = law("return F").replace("import torch.nn as nn\n", "")
    message = refusal(code)
    assert "nn is not imported: add `import torch.nn as nn`" in message


def test_a_long_line_is_quoted_shortened():
    assert quote_line("x = 1\n" + "y = " + "F + " * 40 + "F\n", 2).endswith("…`)")
    assert quote_line("x = 1\n", 3) == "" and quote_line("x = 1\n", None) == ""


def test_a_law_written_with_harmless_standard_modules_is_captured():
    """``@dataclass`` and typing hints look the class's module up while the code runs."""
    code = '''from dataclasses import dataclass
from typing import Tuple

import torch
import torch.nn as nn


@dataclass
class Moduli:
    mu: float = 1.0


class Physics(nn.Module):
    def __init__(self, mu: float = 2.0):
        super().__init__()
        self.mu = nn.Parameter(torch.tensor(Moduli(mu).mu))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        shape: Tuple[int, ...] = F.shape
        return F.reshape(shape) * self.mu
'''
    document = capture_law(code)
    assert [parameter["name"] for parameter in document["parameters"]] == ["mu"]
