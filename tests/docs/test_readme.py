"""The README's taichi_mpm example runs as written (in its own process: it picks float32)."""

import re
import subprocess
import sys
from pathlib import Path

README = Path(__file__).resolve().parents[2] / "README.md"


def test_readme_python_example_runs():
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), re.S)
    assert blocks, "README.md has no python example"
    check = "\nassert np.isfinite(loss) and set(grads.material) == {'E', 'nu', 'yield_stress'}\n"
    result = subprocess.run(
        [sys.executable, "-c", blocks[0] + check], capture_output=True, text=True, timeout=900
    )
    assert result.returncode == 0, result.stderr[-2000:]
