"""The README: short, with the install and test commands CI runs, links that resolve, and a
taichi_mpm example that runs as a script and prints its results."""

import ast
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


def test_the_readme_python_examples_import_only_what_they_use():
    for block in re.findall(r"```python\n(.*?)```", text(), re.S):
        tree = ast.parse(block)
        imported = {
            (alias.asname or alias.name).split(".")[0]
            for node in ast.walk(tree)
            if isinstance(node, ast.Import | ast.ImportFrom)
            for alias in node.names
        }
        used = {node.id for node in ast.walk(tree) if isinstance(node, ast.Name)}
        assert imported <= used, f"imported, never used: {sorted(imported - used)}"


@pytest.mark.slow
def test_the_readme_python_example_runs_as_a_script_and_prints():
    """In its own process: it picks float32."""
    blocks = re.findall(r"```python\n(.*?)```", text(), re.S)
    assert blocks, "README.md has no python example"
    check = (
        "\nimport numpy as np\n"
        "assert np.isfinite(loss) and set(grads.material) == {'E', 'nu', 'yield_stress'}\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", blocks[0] + check], capture_output=True, text=True, timeout=900
    )
    assert result.returncode == 0, result.stderr[-2000:]
    printed = dict(re.findall(r"^dloss/d(\w+) = (\S+)$", result.stdout, re.MULTILINE))
    assert set(printed) == {"E", "nu", "yield_stress"}, result.stdout
    assert re.search(r"^loss \d\.\d+e[-+]\d+$", result.stdout, re.MULTILINE), result.stdout


#: The lines that open each part of the main command's end screen, in the README's order.
SCREEN_PARTS = ("run folder:", "top ", "best:", "ground truth:", "verdict:",
                "free run of the best on the training scene", "free run of the best on the "
                "held-out scene", "its code, with the fitted constants written in:",
                "evaluations", "failures:", "report: sga-agent report")  # fmt: skip


def parts(screen: str) -> list[str]:
    """The parts of an end screen that are there, in the order they come."""
    found = []
    for line in screen.splitlines():
        words = re.sub(r"^\d+ ", "", line.strip())
        found += [part for part in SCREEN_PARTS if words.startswith(part) and part not in found]
    return found


def best_loss(screen: str) -> float:
    return float(re.search(r"^best: \S+, loss (\S+),", screen, re.MULTILINE).group(1))


def piped_search(folder: Path, *options: str) -> str:
    """``sga-agent search --task granular OPTIONS > out.txt``: what the file holds."""
    piped = folder / "out.txt"
    with piped.open("w") as stdout:
        done = subprocess.run(
            [sys.executable, "-m", "sga_agent", "search", "--task", "granular", *options],
            cwd=folder, stdout=stdout, stderr=subprocess.PIPE, text=True, timeout=3600,
        )  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    return piped.read_text(encoding="utf-8")


def readme_screen() -> str:
    return re.search(r"```text\n(.*?)```", text(), re.S).group(1)


@pytest.mark.slow
def test_a_piped_search_prints_the_readme_s_parts_and_a_law_that_compiles(tmp_path):
    """A short search with its output in a file: the law printed is Python (never wrapped)
    and the screen has the README's parts in its order."""
    screen = piped_search(tmp_path, "--iterations", "1", "--exploit", "1", "--explore", "1",
                          "--epochs", "1")  # fmt: skip
    code = re.search(r"written in:\n(.*?)\n\d+ evaluations? ", screen, re.S).group(1)
    compile(code, "out.txt", "exec")
    assert parts(readme_screen()) == list(SCREEN_PARTS)
    shown = [part for part in SCREEN_PARTS if part != "failures:" or part in parts(screen)]
    assert parts(screen) == shown  # a search without failures has no failures line


@pytest.mark.heavy
def test_the_main_command_piped_prints_the_readme_screen_with_a_law_that_compiles(tmp_path):
    """``sga-agent search --task granular > out.txt`` (two to three minutes): the law in the
    file is Python, and the screen has the README's parts and its best loss (within 2x:
    another CPU may differ)."""
    screen = piped_search(tmp_path)
    code = re.search(r"written in:\n(.*?)\n\d+ evaluations? ", screen, re.S).group(1)
    compile(code, "out.txt", "exec")
    readme = readme_screen()
    assert parts(screen) == parts(readme) == list(SCREEN_PARTS)
    assert 0.5 < best_loss(screen) / best_loss(readme) < 2, (screen, readme)
