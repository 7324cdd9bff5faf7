"""Response parsing and the static checks of solution code."""

import textwrap
from pathlib import Path

import pytest

from sga_agent.parsing import CodeRejected, check_code, parse_response
from sga_agent.registry import load_task, task_names

LAWS = sorted((Path(__file__).resolve().parents[2] / "examples" / "laws").glob("*.py"))

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
    with pytest.raises(CodeRejected) as caught:
        check_code(code, kind)
    return str(caught.value)


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
def test_seed_solutions_of_the_registered_tasks_pass(name):
    task = load_task(name)
    check_code(task.seed_solution(), task.kind)


@pytest.mark.parametrize("path", LAWS, ids=lambda path: path.stem)
def test_example_laws_pass(path):
    check_code(path.read_text(encoding="utf-8"), "equation")


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
    check_code(code, "equation")


def test_allowed_imports_can_be_widened_but_not_to_forbidden_modules():
    code = law("return F", head="import scipy\n")
    check_code(code, "equation", allowed_imports=["torch", "scipy"])
    with pytest.raises(CodeRejected, match="importing 'os' is not allowed"):
        check_code(law("return F", head="import os\n"), "equation", ["torch", "os"])


def test_molecule_with_backslash_smiles_passes():
    check_code('SMILES = "C/C=C\\N"\ncoordinates = [[0, 0, 0], [1.2, -0.5, 1e-3]]\n', "entity")


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
        ("return F", "import scipy\n", "only torch, math and numpy may be imported"),
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
    assert expected in rejection(code)


def test_syntax_errors_name_the_line():
    message = rejection("import torch\n\nclass Physics(nn.Module:\n    pass\n")
    assert message.startswith("line 3: the code is not valid Python (")


def test_problems_are_listed_by_line_and_capped():
    code = "\n".join(f"x{i} = eval('{i}')" for i in range(8))
    lines = rejection(code).splitlines()
    assert [line.split(":")[0] for line in lines[:5]] == [f"line {i}" for i in range(1, 6)]
    assert lines[5] == "(and 4 more problems)"  # three evals and the missing class


@pytest.mark.parametrize(
    ("code", "expected"),
    [
        (
            'import os\nSMILES = "CCO"\ncoordinates = [[0, 0, 0]]',
            "line 1: importing 'os' is not allowed: solutions may not reach files, processes or "
            "the network; this task's code may not import anything",
        ),
        (
            'SMILES = "CCO"\ncoordinates = [[0, 0, 0]]\nprint(SMILES)',
            "line 3: only assignments of literal values",
        ),
        (
            'SMILES = "CC" + "O"\ncoordinates = [[0, 0, 0]]',
            "line 1: the value of 'SMILES' must be a literal",
        ),
        (
            'SMILES = "CCO"\ncoordinates = [[0.0, 0.0, 0.0] for _ in range(3)]',
            "line 2: the value of 'coordinates' must be a literal",
        ),
        ('SMILES = "CCO"', "the code must assign coordinates"),
        ("SMILES = 3\ncoordinates = [[0, 0, 0]]", "line 1: SMILES must be a string literal"),
        (
            'SMILES = "CCO"\ncoordinates = [[0, True, "a"]]',
            "line 2: coordinates must be a non-empty list of rows of numbers",
        ),
        (
            'SMILES: __import__("os") = "CCO"\ncoordinates = [[0, 0, 0]]',
            "'__import__' is not allowed",
        ),
        (
            'def f():\n    pass\nSMILES = "C"\ncoordinates = [[0, 0, 0]]',
            "line 1: only assignments of literal values",
        ),
    ],
    ids=[
        "import",
        "call",
        "arithmetic",
        "comprehension",
        "missing",
        "smiles-type",
        "coordinate-type",
        "annotation",
        "function",
    ],
)
def test_entity_code_is_literal_data_only(code, expected):
    assert expected in rejection(code, kind="entity")


def test_unknown_kind_is_a_programming_error():
    with pytest.raises(ValueError, match="kind must be one of"):
        check_code("x = 1", "formula")
