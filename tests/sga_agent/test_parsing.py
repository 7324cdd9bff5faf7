"""Response parsing and the static checks of solution code."""

import textwrap

import pytest

from sga_agent.parsing import check_candidate, check_code, parse_response
from sga_agent.registry import load_task, task_names
from sga_agent.task import CodeRejected, PromptParts
from tests.tasks.observed.conftest import ready_task

RESPONSE = """\
Here is my answer.

### Analysis

#### Iteration 1
The linear law misses large strains, e.g.
```python
stress = mu * strain
```

#### Iteration 2
Better, but too stiff.

### Step-by-Step Plan

1. Keep the shear term.
```
# Code
not a heading: it is inside a block
```

### Code

```python
import torch
# ### Code (a comment, not a heading)
x = torch.ones(3)
```
"""


def law(forward_body: str = "return F", head: str = "", init: str = "") -> str:
    """A valid law whose forward runs ``forward_body``, with ``head`` before the class."""
    return textwrap.dedent(head) + textwrap.dedent(f"""
        import torch
        import torch.nn as nn


        class Physics(nn.Module):
            def __init__(self, alpha: float = 1.0{init}):
                super().__init__()
                self.alpha = nn.Parameter(torch.tensor(alpha))

            def forward(self, F: torch.Tensor) -> torch.Tensor:
                {forward_body}
        """)


def rejection(code: str, kind: str = "equation") -> str:
    """The message of the generic checks' rejection of ``code``."""
    with pytest.raises(CodeRejected) as caught:
        check_code(code, kind)
    return str(caught.value)


class ListTask:
    """A task whose solutions are a list literal of numbers; it checks that shape itself."""

    name = "numbers"
    description = "a list of numbers"
    kind = "entity"

    def __init__(self) -> None:
        self.checked: list[str] = []

    def seed_solution(self) -> str:
        return "values = [1.0, 2.0]\n"

    def prompt_parts(self) -> PromptParts:
        return PromptParts("a tester", "numbers", "values = [...]", "a list")

    def check_solution(self, code: str) -> None:
        self.checked.append(code)
        if not code.startswith("values = ["):
            raise CodeRejected("the code must start with values = [")


# --- parse_response -------------------------------------------------------------------------


def test_sections_are_split_at_their_headings():
    parsed = parse_response(RESPONSE)
    assert set(parsed.sections) == {"analysis", "plan", "code"}
    assert parsed.sections["analysis"].startswith("#### Iteration 1")
    assert "#### Iteration 2\nBetter, but too stiff." in parsed.sections["analysis"]
    assert parsed.sections["plan"].startswith("1. Keep the shear term.")
    assert "not a heading" in parsed.sections["plan"]
    assert parsed.sections["code"].startswith("```python\nimport torch")


def test_the_last_python_block_is_the_code():
    code = parse_response(RESPONSE).code
    assert code == "import torch\n# ### Code (a comment, not a heading)\nx = torch.ones(3)\n"


def test_untagged_blocks_count_other_languages_do_not():
    parsed = parse_response("```\nx = 1\n```\n\n```bash\nls\n```\n")
    assert parsed.code == "x = 1\n"


def test_numbered_and_bold_headings_are_recognised():
    parsed = parse_response("## 1. Analysis\nA\n## **Step-by-step plan:**\nP\n# Code\nC\n")
    assert parsed.sections == {"analysis": "A", "plan": "P", "code": "C"}


def test_missing_code_block_gives_none():
    parsed = parse_response("### Analysis\nNothing to propose.\n")
    assert parsed.code is None
    assert parsed.sections == {"analysis": "Nothing to propose."}


def test_truncated_code_block_runs_to_the_end():
    assert parse_response("### Code\n```python\nx = 1\ny = (").code == "x = 1\ny = (\n"


# --- check_code: what passes ----------------------------------------------------------------


@pytest.mark.parametrize("name", task_names())
def test_seed_solutions_of_the_registered_tasks_pass(name, tmp_path):
    task = ready_task(name, tmp_path)
    check_candidate(task.seed_solution(), task)


def test_allowed_imports_can_be_widened_but_not_to_forbidden_modules():
    code = law("return F", head="import scipy\n")
    check_code(code, "equation", allowed_imports=["torch", "scipy"])
    with pytest.raises(CodeRejected, match="importing 'os' is not allowed"):
        check_code(law("return F", head="import os\n"), "equation", ["torch", "os"])


# --- check_code: what is rejected, and how it is said ---------------------------------------


@pytest.mark.parametrize(
    ("code", "expected"),
    [
        ('import os\nos.system("ls")', "line 1: importing 'os' is not allowed"),
        ('open("/etc/passwd")', "'open' is not allowed"),
        ('__import__("os")', "'__import__' is not allowed"),
        ('import torch\ntorch.hub.load("a/b", "m")', "line 2: 'torch.hub.load' is not allowed"),
        ("().__class__.__bases__[0].__subclasses__()", "dunder attribute"),
        ('import torch\ngetattr(torch, "lo" + "ad")("f")', "plain string literal"),
    ],
    ids=["os-system", "open", "dunder-import", "torch-hub", "subclasses", "computed-getattr"],
)
def test_hostile_snippets_are_rejected(code, expected):
    assert expected in rejection(code)


@pytest.mark.parametrize(
    ("body", "head", "expected"),
    [
        ("return F", "import subprocess\n", "importing 'subprocess' is not allowed"),
        ("return F", "import scipy\n", "only torch, math, numpy and standard helpers such as"),
        ("return F", "from torch import hub\n", "'torch.hub' is not allowed"),
        ("return F", "from torch.utils.cpp_extension import load_inline\n", "cpp_extension"),
        ("return F", "from torch import *\n", "import the names you use explicitly"),
        ("return F", "from . import helpers\n", "relative imports are not allowed"),
        ("return F", "import torch._dynamo\n", "'torch._dynamo' is not allowed"),
        ("return eval('F')", "", "'eval' is not allowed"),
        ("exec('x = 1'); return F", "", "'exec' is not allowed"),
        ("compile('1', 'f', 'eval'); return F", "", "'compile' is not allowed"),
        ("return globals()['F']", "", "'globals' is not allowed"),
        ("return vars(self)['alpha'] * F", "", "'vars' is not allowed"),
        ("breakpoint(); return F", "", "'breakpoint' is not allowed"),
        ("input(); return F", "", "without a terminal"),
        ("exit(); return F", "", "'exit' is not allowed"),
        ("setattr(self, name, 1); return F", "", "setattr() needs a plain string literal"),
        ("g = getattr; return F", "", "'getattr' may only be called directly"),
        ("return getattr(F, '__class__')", "", "accessing '__class__' is not allowed"),
        ("return F.__class__", "", "'F.__class__' is not allowed"),
        ("return self.forward.__globals__", "", "__globals__"),
        ("return __builtins__", "", "the name '__builtins__' is not allowed"),
        ("torch.save(F, 'f.pt'); return F", "", "'torch.save' is not allowed"),
        ("return torch.load('f.pt')", "", "'torch.load' is not allowed"),
        ("return torch.jit.script(F)", "", "'torch.jit' is not allowed"),
        ("return torch.compile(self)(F)", "", "'torch.compile' is not allowed"),
        ("return torch.ops.aten.abs(F)", "", "'torch.ops' is not allowed"),
        ("return torch.classes.x(F)", "", "'torch.classes' is not allowed"),
        ("return torch._C._nn(F)", "", "'torch._C._nn' is not allowed"),
        ("torch.os.system('ls'); return F", "", "'torch.os' is not allowed"),
        ("F.numpy().tofile('f'); return F", "", "'F.numpy().tofile' is not allowed"),
        ("return torch.tensor(np.load('f.npy'))", "import numpy as np\n", "'np.load' is not"),
        ("return torch.tensor(np.fromfile('f'))", "import numpy as np\n", "'np.fromfile' is not"),
        ("return F", "import numpy\nnumpy.save('f', 1)\n", "'numpy.save' is not allowed"),
    ],
)
def test_forbidden_constructs_are_rejected_with_their_line(body, head, expected):
    message = rejection(law(body, head=head))
    assert expected in message
    # the law's forward body is on line 12, moved down by the head and the blank line after it
    line = head.count("\n") if body == "return F" else 12 + head.count("\n")
    assert message.startswith(f"line {line}: ")


def test_syntax_errors_name_the_line():
    message = rejection("import torch\n\nclass Physics(nn.Module:\n    pass\n")
    assert message.startswith("line 3: the code is not valid Python (")


def test_problems_are_listed_by_line_and_capped():
    code = "\n".join(f"x{i} = eval('{i}')" for i in range(8))
    with pytest.raises(CodeRejected) as caught:
        check_candidate(code, load_task("elastic"))
    lines = str(caught.value).splitlines()
    assert [line.split(":")[0] for line in lines[:5]] == [f"line {i}" for i in range(1, 6)]
    assert lines[5] == "(and 4 more problems)"  # three evals and the missing class


def test_unknown_kind_is_a_programming_error():
    with pytest.raises(ValueError, match="kind must be one of"):
        check_code("x = 1", "formula")


# --- check_candidate: the generic rules, then the task's own check ----------------------------


def test_a_task_check_runs_after_the_generic_rules_and_both_are_reported():
    task = ListTask()
    check_candidate("values = [3.0]\n", task)
    with pytest.raises(CodeRejected) as caught:
        check_candidate("import os\nx = 1\n", task)
    assert caught.value.problems == [
        (1, "importing 'os' is not allowed: solutions may not reach files, processes or the "
            "network; this task's code may not import anything"),
        (0, "the code must start with values = ["),
    ]  # fmt: skip
    assert str(caught.value).splitlines()[1] == "the code must start with values = ["


def test_code_that_does_not_parse_is_not_shown_to_the_task():
    task = ListTask()
    with pytest.raises(CodeRejected, match="line 1: the code is not valid Python"):
        check_candidate("values = [\n", task)
    assert task.checked == []


def test_a_task_without_a_check_gets_the_generic_rules_only():
    plain = type("Plain", (), {"kind": "entity"})()
    check_candidate("anything = 1\n", plain)
    with pytest.raises(CodeRejected, match="'eval' is not allowed"):
        check_candidate("x = eval('1')\n", plain)
