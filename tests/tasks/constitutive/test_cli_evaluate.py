"""`sga-agent evaluate` on broken law files: a one-line reason and a non-zero exit, no crash,
whether the static checks, the confined capture or the trusted fit refuse the law."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

BROKEN = {
    # refused by the static checks, before the sandbox
    "syntax": ("class Physics(nn.Module:\n", "the code is not valid Python"),
    "missing class": ("import torch\n\nclass Law:\n    pass\n", "no top-level class 'Physics'"),
    # refused by the capture
    "branch on a tensor": (
        "import torch.nn as nn\n\nclass Physics(nn.Module):\n"
        "    def forward(self, F):\n        if F.sum() > 0:\n            return F\n"
        "        return -F\n",
        "use torch.where(condition, a, b) instead of an if",
    ),
    # refused by the fit
    "wrong shape": (
        "import torch.nn as nn\n\nclass Physics(nn.Module):\n"
        "    def forward(self, F):\n        return F.sum(-1)\n",
        "must return F_corrected of shape (1000, 3, 3)",
    ),
    "nan": (
        "import torch\nimport torch.nn as nn\n\nclass Physics(nn.Module):\n"
        "    def forward(self, F):\n        return F / (F - F)\n",
        "non-finite",
    ),
}


@pytest.mark.slow
@pytest.mark.parametrize("case", list(BROKEN))
def test_broken_law_files(case, tmp_path):
    code, reason = BROKEN[case]
    law = tmp_path / "law.py"
    law.write_text(code)
    run = subprocess.run(
        [sys.executable, "-m", "sga_agent", "evaluate", "--task", "plasticine", str(law)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode == 1, run.stderr
    lines = [line for line in run.stderr.splitlines() if line.startswith("invalid:")]
    assert len(lines) == 1 and reason in lines[0], run.stderr
    assert "Traceback" not in run.stderr + run.stdout


@pytest.mark.slow
def test_task_options_reach_the_evaluation():
    law = Path(__file__).resolve().parents[3] / "examples" / "laws" / "von_mises.py"
    command = [sys.executable, "-m", "sga_agent", "evaluate", "--task", "plasticine", str(law)]
    run = subprocess.run(
        [*command, "--epochs", "1", "--option", "steps=100", "--option", "optimizer=lbfgs",
         "--json"],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    evaluation = json.loads(run.stdout)
    assert "L-BFGS" in evaluation["feedback"] and evaluation["loss"] < 1e-8
    bad = subprocess.run([*command, "--option", "steps"], capture_output=True, text=True)
    assert bad.returncode == 2 and "is not KEY=VALUE" in bad.stderr
