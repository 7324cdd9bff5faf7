"""The README's taichi_mpm example runs as written (in its own process: it picks float32)."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[2] / "README.md"


@pytest.mark.slow
def test_readme_python_example_runs():
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), re.S)
    assert blocks, "README.md has no python example"
    check = "\nassert np.isfinite(loss) and set(grads.material) == {'E', 'nu', 'yield_stress'}\n"
    result = subprocess.run(
        [sys.executable, "-c", blocks[0] + check], capture_output=True, text=True, timeout=900
    )
    assert result.returncode == 0, result.stderr[-2000:]


@pytest.mark.heavy
def test_readme_sysid_example_runs(tmp_path):
    """The system-identification example: make the observation, then the python block."""
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), re.S)
    example = next(block for block in blocks if "load_observation" in block)
    script = README.parent / "scripts" / "make_observation.py"
    subprocess.run(
        [sys.executable, str(script), "observed.npz", "--material", "vonmises", "--noise", "0.01"],
        cwd=tmp_path,
        check=True,
        capture_output=True,
        timeout=600,
    )
    check = "\nassert abs(result.best.values['yield_stress'] / 2e3 - 1) < 0.1\n"
    result = subprocess.run(
        [sys.executable, "-c", example + check],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert result.returncode == 0, result.stderr[-2000:]


@pytest.mark.heavy
def test_readme_bridges_example_runs():
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), re.S)
    example = next(block for block in blocks if "trajectory_loss" in block)
    check = "\nassert result.loss > 1e-9 and plastic.yield_stress.grad < 0\n"
    result = subprocess.run(
        [sys.executable, "-c", example + check], capture_output=True, text=True, timeout=900
    )
    assert result.returncode == 0, result.stderr[-2000:]
