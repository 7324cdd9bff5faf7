"""The README: short, with the install and test commands CI runs, links that resolve, and a
taichi_mpm example that runs as a script and prints its results."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
#: .ci/run runs these two, in this form; users copy them from the README.
INSTALL = (
    "python3 -m venv .venv && . .venv/bin/activate && pip install torch==2.13.0 && "
    'pip install -e ".[test]"'
)
TEST = 'python -m pytest -q -m "not heavy"'


def text() -> str:
    return README.read_text(encoding="utf-8")


def test_the_readme_is_short():
    assert len(text().splitlines()) <= 200


def test_the_readme_gives_the_install_and_test_commands():
    lines = text().splitlines()
    assert INSTALL in lines and TEST in lines


def test_the_readme_links_resolve():
    targets = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text())
    local = [target for target in targets if "://" not in target]
    assert local, "README.md links to no file"
    assert [target for target in local if not (ROOT / target).exists()] == []


def test_the_readme_shows_no_commit_history():
    """History (commit hashes, 'measured on <hash>') belongs in CHANGELOG.md."""
    assert not re.search(r"`[0-9a-f]{7}`", text())


def test_the_main_commands_output_is_shown():
    assert "sga-agent search --task granular" in text()
    block = re.search(r"```text\n(.*?)```", text(), re.S).group(1)
    assert "run folder: runs/granular-" in block and "report: sga-agent report" in block


@pytest.mark.slow
def test_the_readme_python_example_runs_as_a_script_and_prints():
    """In its own process: it picks float32."""
    blocks = re.findall(r"```python\n(.*?)```", text(), re.S)
    assert blocks, "README.md has no python example"
    check = "\nassert np.isfinite(loss) and set(grads.material) == {'E', 'nu', 'yield_stress'}\n"
    result = subprocess.run(
        [sys.executable, "-c", blocks[0] + check], capture_output=True, text=True, timeout=900
    )
    assert result.returncode == 0, result.stderr[-2000:]
    printed = dict(re.findall(r"^dloss/d(\w+) = (\S+)$", result.stdout, re.MULTILINE))
    assert set(printed) == {"E", "nu", "yield_stress"}, result.stdout
    assert re.search(r"^loss \d\.\d+e[-+]\d+$", result.stdout, re.MULTILINE), result.stdout
