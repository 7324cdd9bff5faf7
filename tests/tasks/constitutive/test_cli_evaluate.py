"""`sga-agent evaluate` on broken law files: a one-line reason and a non-zero exit, no crash."""

import subprocess
import sys

import pytest

BROKEN = {
    "syntax": ("class Physics(nn.Module:\n", "does not compile: SyntaxError"),
    "missing class": ("import torch\n\nclass Law:\n    pass\n", "no class named 'Physics'"),
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
