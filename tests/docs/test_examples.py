"""The site's examples (files under examples/, pulled into docs/ by snippets) run as written,
and print what the site shows (docs/outputs/*.txt, compared with every digit masked).

After a deliberate change of an example's output, ``SGA_UPDATE_DOC_OUTPUTS=1 python -m pytest
-q tests/docs`` rewrites the recorded outputs.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
EXAMPLES = ROOT / "examples"
OUTPUTS = DOCS / "outputs"
UPDATE = os.environ.get("SGA_UPDATE_DOC_OUTPUTS") == "1"
#: A snippet line of a page: --8<-- "path from the repository root".
SNIPPET = re.compile(r'^-+8<-+\s+"([^"]+)"', re.MULTILINE)
#: Taichi's own log lines ("[Taichi] Starting on arch=x64", "[I 11/25/26 ...] ..."), which the
#: site leaves out.
TAICHI_LOG = re.compile(r"^\[(Taichi|[IWE] \d)")


def included() -> set[Path]:
    """Every file a page of the site (or the changelog page) pulls in."""
    pages = [*DOCS.rglob("*.md")]
    return {ROOT / path for page in pages for path in SNIPPET.findall(page.read_text("utf-8"))}


def environment(**extra: str) -> dict[str, str]:
    path = os.pathsep.join(filter(None, [extra.pop("PYTHONPATH", ""), str(ROOT),
                                         os.environ.get("PYTHONPATH")]))  # fmt: skip
    return {**os.environ, "PYTHONPATH": path, "PYTHONUNBUFFERED": "1", "COLUMNS": "100",
            "LITELLM_LOCAL_MODEL_COST_MAP": "True", **extra}  # fmt: skip


def run(command: list[str], cwd: Path = ROOT, env: dict | None = None, timeout: float = 600):
    """Run ``command``; its stdout and stderr together, as a terminal would show them."""
    done = subprocess.run(command, cwd=cwd, env=env or environment(), stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True, timeout=timeout)  # fmt: skip
    assert done.returncode == 0, done.stdout[-3000:]
    return done.stdout


def shown(output: str) -> str:
    """``output`` as the site shows it: without Taichi's log lines and trailing blanks."""
    lines = [line.rstrip() for line in output.splitlines() if not TAICHI_LOG.match(line)]
    return "\n".join(lines).strip("\n") + "\n"


#: A number as a screen writes it: 3, 0.72, 2.1e-06, 6.16e+10.
NUMBER = re.compile(r"\d+(?:\.\d+)?(?:e[-+]?\d+)?")


def assert_shown_on_the_site(name: str, output: str, numbers: bool = False) -> None:
    """``output`` matches docs/outputs/NAME.txt, digits masked (values, times, dates vary);
    with ``numbers``, each number masked whole (its digits may differ in count on another CPU)."""
    path = OUTPUTS / f"{name}.txt"
    text = shown(output)
    if UPDATE:
        path.write_text(text, encoding="utf-8")
        return
    recorded = path.read_text(encoding="utf-8")

    def mask(value: str) -> str:
        return NUMBER.sub("#", value) if numbers else re.sub(r"\d", "#", value)

    assert mask(text) == mask(recorded), (
        f"{path.relative_to(ROOT)} no longer shows what the example prints; if the change is "
        f"meant, rerun with SGA_UPDATE_DOC_OUTPUTS=1.\nNow:\n{text}\nOn the site:\n{recorded}"
    )


def test_every_example_is_on_the_site_and_every_included_file_exists():
    files = included()
    assert all(path.is_file() for path in files), sorted(p for p in files if not p.is_file())
    scripts = {p for p in EXAMPLES.glob("*.py")}
    plugin = {EXAMPLES / "numbers_plugin" / n
              for n in ("sga_numbers.py", "test_sga_numbers.py", "pyproject.toml")}  # fmt: skip
    assert scripts | plugin <= files, sorted(scripts | plugin - files)
    assert set(OUTPUTS.glob("*.txt")) <= files, "a recorded output no page shows"
    # Every other example on the site is a ground-truth law, run by the constitutive tests
    # (tests/tasks/constitutive: test_law_shape.py, test_cli_evaluate.py).
    others = {p for p in files if p.is_relative_to(EXAMPLES)} - scripts - plugin
    assert all(p.parent == EXAMPLES / "laws" for p in others), sorted(others)


@pytest.mark.slow
def test_simulate_cube():
    output = run([sys.executable, "examples/simulate_cube.py", "--steps", "200"])
    gradients = dict(re.findall(r"dloss/d(\w+) = (\S+)", output))
    assert set(gradients) == {"E", "nu", "yield_stress"}
    assert float(gradients["yield_stress"]) > 0  # the observation's yield stress is lower
    assert_shown_on_the_site("simulate_cube", output)


@pytest.mark.slow
def test_bridges_rollout():
    output = run([sys.executable, "examples/bridges_rollout.py", "--steps", "200"])
    loss = float(re.search(r"^loss (\S+)", output, re.MULTILINE).group(1))
    gradient = float(re.search(r"dloss/dyield_stress (\S+)", output).group(1))
    assert loss > 1e-9 and gradient < 0  # the law's yield stress is too low
    assert_shown_on_the_site("bridges_rollout", output)


@pytest.mark.slow
def test_sysid_cube():
    output = run([sys.executable, "examples/sysid_cube.py", "--steps", "300"])
    fitted = float(re.search(r"yield_stress\s+(\S+)\s+\+-", output).group(1))
    assert abs(fitted / 2e3 - 1) < 0.05 and "all parameters identified" in output
    assert_shown_on_the_site("sysid_cube", output)


@pytest.mark.slow
def test_the_held_out_floors():
    output = run([sys.executable, "-m", "tasks.constitutive.held_out"])
    assert output.count("held-out free-run RMS error") == 5
    command = "$ python -m tasks.constitutive.held_out\n"
    assert_shown_on_the_site("held_out_floors", command + output, numbers=True)


#: The short search of the tasks page, as written there.
SHORT_ELASTIC_SEARCH = ["search", "--task", "elastic", "--option", "steps=200", "--iterations",
                        "1", "--exploit", "1", "--explore", "1", "--epochs", "2", "--workers",
                        "2"]  # fmt: skip


@pytest.mark.slow
def test_the_short_elastic_search_of_the_tasks_page(tmp_path: Path):
    """The page's command ends with the lines the page shows: the best's ratio to the seed and
    the truth's, the verdict, whether the observation determines the law and the two free
    runs."""
    command = " ".join(["sga-agent", *SHORT_ELASTIC_SEARCH])
    assert command in " ".join((DOCS / "tasks.md").read_text("utf-8").replace("\\\n", " ").split())
    output = run([sys.executable, "-m", "sga_agent", *SHORT_ELASTIC_SEARCH, "--out-dir",
                  str(tmp_path)], env=environment(COLUMNS="400"))  # fmt: skip
    parts = ("best:", "ground truth:", "verdict:", "identifiability:", "free run of the best")
    lines = [line.rstrip() for line in output.splitlines() if line.startswith(parts)]
    assert len(lines) == 6, output
    shown_lines = "\n".join(lines).replace(str(tmp_path), "OUT")  # the scene file's folder
    assert_shown_on_the_site("elastic_verdict", shown_lines, numbers=True)


@pytest.mark.slow
def test_the_plugin_tutorial(tmp_path: Path):
    """The tutorial's commands: pip installs the plugin, its conformance test passes,
    sga-agent lists it, evaluates a solution, searches with the plugin's own proposer
    (capture and fit processes included) and replays the recorded search."""
    source = shutil.copytree(EXAMPLES / "numbers_plugin", tmp_path / "numbers_plugin")
    site = tmp_path / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation",
         "--target", str(site), str(source)],
        check=True, capture_output=True, timeout=300,
    )  # fmt: skip
    assert (site / "sga_numbers.py").is_file()
    env = environment(PYTHONPATH=str(site))
    agent = [sys.executable, "-m", "sga_agent"]

    checked = run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                   "numbers_plugin/test_sga_numbers.py"], cwd=tmp_path, env=env)  # fmt: skip
    assert "1 passed" in checked  # the plugin's own conformance test

    listed = run([*agent, "tasks"], cwd=tmp_path, env=env)
    assert re.search(r"^numbers\s+entity\s+Find three hidden numbers", listed, re.MULTILINE)

    evaluated = run([*agent, "evaluate", "--task", "numbers", "numbers_plugin/guess.json"],
                    cwd=tmp_path, env=env)  # fmt: skip
    assert "squared distance 0.25" in evaluated
    assert_shown_on_the_site("numbers_evaluate", evaluated)

    searched = run([*agent, "search", "--task", "numbers", "--seed", "0", "--out-dir", "runs"],
                   cwd=tmp_path, env=env)  # fmt: skip
    assert "25 evaluations (25 ok)" in searched
    assert_shown_on_the_site("numbers_search", searched)

    recorded = re.search(r"^run folder: (\S+)$", searched, re.MULTILINE).group(1)
    replay = [*agent, "search", "--task", "numbers", "--replay", recorded, "--out-dir", "replayed"]
    replayed = run(replay, cwd=tmp_path, env=env)
    best = re.compile(r"^best: .*$", re.MULTILINE)
    assert best.search(replayed).group(0) == best.search(searched).group(0)
