"""The benchmark grid (``benchmarks/backbones.py``, ``benchmarks/presets.py``) end to end on two
cheap test-double tasks registered through a throw-away entry point: every cell is a real
search run with sandboxed evaluations, in parallel worker processes."""

from __future__ import annotations

import csv
import importlib.util
import json
import os
import shutil
import statistics
import struct
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest
from click.testing import CliRunner

from sga_agent.benchmark import GridError, Method, plan_cells
from sga_agent.benchmark.chart import RANKS_SIZE
from sga_agent.benchmark.table import Score, markdown, number, rank
from sga_agent.report.plots import DPI

REPO = Path(__file__).resolve().parents[2]
TASKS = "number-a,number-b"
ENTRY_POINTS = """[sga_agent.tasks]
number-a = tests.benchmarks.doubles:NumberTaskA
number-b = tests.benchmarks.doubles:NumberTaskB
"""


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder whose dist-info registers the two number tasks (as a plugin package would)."""
    folder = tmp_path_factory.mktemp("site")
    info = folder / "number_tasks-0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: number-tasks\nVersion: 0\n")
    (info / "entry_points.txt").write_text(ENTRY_POINTS)
    return folder


@pytest.fixture
def registered(site: Path, monkeypatch: pytest.MonkeyPatch) -> dict[str, str]:
    """The number tasks registered here and in every process started with the returned env."""
    monkeypatch.syspath_prepend(str(site))
    path = os.pathsep.join(filter(None, [str(site), str(REPO), os.environ.get("PYTHONPATH")]))
    monkeypatch.setenv("PYTHONPATH", path)
    return {**os.environ, "PYTHONPATH": path}


def script(name: str, *args: str, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, str(REPO / "benchmarks" / f"{name}.py"), *args]
    return subprocess.run(command, env=env, capture_output=True, text=True, timeout=300)


def load_script(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(
        f"bench_{name}", REPO / "benchmarks" / f"{name}.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


def cell_losses(out: Path, task: str, method: str) -> list[float]:
    """The best losses in the cells' own summary.json files, seed by seed."""
    losses = []
    for seed in (0, 1):
        (summary,) = (out / task / method / f"seed-{seed}").glob("*/summary.json")
        losses.append(json.loads(summary.read_text())["best"]["loss"])
    return losses


def event_logs(out: Path) -> dict[Path, bytes]:
    return {path: path.read_bytes() for path in out.glob("*/*/seed-*/*/events.jsonl")}


@pytest.mark.heavy
def test_backbones_grid_writes_table_and_chart_and_resumes(tmp_path, registered):
    recorded = tmp_path / "recorded"  # the runs replayed below: one per task and seed
    result = script("backbones", "--tasks", TASKS, "--models", "builtin", "--preset", "cot",
                    "--seeds", "0,1", "--out-dir", str(recorded), env=registered)  # fmt: skip
    assert result.returncode == 0, result.stderr

    out = tmp_path / "bench"
    args = ["--tasks", TASKS, "--models", f"builtin,replay:{recorded}", "--preset", "quick",
            "--set", "iterations=2", "--seeds", "0,1", "--parallel", "2",
            "--out-dir", str(out)]  # fmt: skip
    result = script("backbones", *args, env=registered)
    assert result.returncode == 0, result.stderr
    assert "8 cells: 0 finished (skipped), 0 to resume, 8 to start; 2 at once" in result.stderr

    # table.csv holds the mean and sample std of the cells' own final losses
    rows = {row["task"]: row for row in csv.DictReader((out / "table.csv").open())}
    md = (out / "table.md").read_text()
    for task in ("number-a", "number-b"):
        assert rows[task]["seeds"] == "2"
        for method, label in (("builtin", "builtin"), ("replay-recorded", "replay:recorded")):
            losses = cell_losses(out, task, method)
            assert float(rows[task][f"{label} mean"]) == pytest.approx(statistics.fmean(losses))
            assert float(rows[task][f"{label} std"]) == pytest.approx(statistics.stdev(losses))
            assert rows[task][f"{label} n"] == "2"
        builtin = statistics.fmean(cell_losses(out, task, "builtin"))
        replay = statistics.fmean(cell_losses(out, task, "replay-recorded"))
        assert builtin < replay  # the replay has answers for the first iteration only
        assert f"| {task} | 2 | **{number(float(rows[task]['builtin mean']))} ± " in md
    assert "| builtin | replay:recorded |" in md
    ranks = list(csv.reader((out / "ranks.csv").open()))
    assert ranks[0] == ["method", "number-a", "number-b", "mean rank"]
    assert ranks[1] == ["builtin", "1", "1", "1.0"]
    assert ranks[2] == ["replay:recorded", "2", "2", "2.0"]
    assert png_size(out / "ranks.png") == (round(RANKS_SIZE[0] * DPI), round(RANKS_SIZE[1] * DPI))
    assert result.stdout.startswith("Final best loss per task")

    # again: nothing runs; then a deleted cell starts again and a killed one is resumed
    before = event_logs(out)
    result = script("backbones", *args, env=registered)
    assert result.returncode == 0, result.stderr
    assert "8 cells: 8 finished (skipped), 0 to resume, 0 to start" in result.stderr
    assert event_logs(out) == before

    table = (out / "table.csv").read_text()
    deleted = out / "number-b" / "builtin" / "seed-1"
    shutil.rmtree(deleted)
    (killed,) = (out / "number-a" / "builtin" / "seed-0").glob("*/")
    events = (killed / "events.jsonl").read_text().splitlines(keepends=True)
    cut = next(i for i, line in enumerate(events) if '"iteration_done"' in line)
    (killed / "events.jsonl").write_text("".join(events[: cut + 1]))  # killed after iteration 1
    (killed / "summary.json").unlink()
    result = script("backbones", *args, env=registered)
    assert result.returncode == 0, result.stderr
    assert "8 cells: 6 finished (skipped), 1 to resume, 1 to start" in result.stderr
    after = event_logs(out)
    unchanged = [p for p in before if killed not in p.parents and deleted not in p.parents]
    assert len(unchanged) == 6 and all(after[path] == before[path] for path in unchanged)
    lines = (killed / "events.jsonl").read_text().splitlines()
    resumed = [json.loads(line) for line in lines[cut + 1 :]]
    assert resumed[0]["type"] == "resumed"
    first_iteration = sum(1 for line in events[: cut + 1] if '"type": "evaluation"' in line)
    evaluated = [e["candidate"] for e in resumed if e["type"] == "evaluation"]
    assert (
        first_iteration == 7 and len(evaluated) == 6 and all(c.startswith("02-") for c in evaluated)
    )
    assert (out / "table.csv").read_text() == table  # the same seeds give the same results


@pytest.mark.slow
def test_presets_grid_runs_each_preset_with_one_proposer(tmp_path, registered):
    out = tmp_path / "presets"
    args = ["--tasks", "number-a", "--model", "builtin", "--presets", "quick,cot",
            "--set", "iterations=1", "--out-dir", str(out)]  # fmt: skip
    result = script("presets", *args, env=registered)
    assert result.returncode == 0, result.stderr
    assert "| task | seeds | quick | cot |" in (out / "table.md").read_text()
    configs = [json.loads(p.read_text())["config"] for p in sorted(out.glob("*/*/*/*/config.json"))]
    assert [(c["preset"], c["loop"]["explore"], c["loop"]["iterations"]) for c in configs] == [
        ("cot", 0, 1), ("quick", 4, 1),
    ]  # fmt: skip


@pytest.mark.parametrize(
    ("name", "args", "fragment"),
    [
        ("backbones", ["--tasks", "number-c", "--models", "builtin"],
         "no task named 'number-c' is registered"),
        ("backbones", ["--tasks", "number-a", "--models", "gpt-4o"],
         "method 'gpt-4o' on task 'number-a': model 'gpt-4o' needs a provider prefix"),
        ("backbones", ["--tasks", "number-a", "--models", "builtin:gp"],
         "task 'number-a' offers 'builtin:nudge', not 'builtin:gp'"),
        ("backbones", ["--tasks", "number-a", "--models", "replay:/nonexistent"],
         "replay:/nonexistent: no such folder"),
        ("backbones", ["--tasks", "number-a", "--models", "builtin", "--seeds", "0,x"],
         "give integers separated by commas"),
        ("backbones", ["--tasks", "number-a", "--models", "builtin", "--set", "iteration=2"],
         "no search setting 'iteration'"),
        ("backbones", ["--tasks", "number-a", "--models", "builtin", "--set", "seed=2"],
         "seed is set by --seeds"),
        ("backbones", ["--tasks", "number-a", "--models", "builtin", "--set", "bilevel=maybe"],
         "bilevel takes a bool"),
        ("backbones", ["--tasks", "number-a", "--models", "a=builtin,a=builtin:nudge"],
         "would share the folder 'a'"),
        ("presets", ["--tasks", "number-a", "--model", "builtin", "--presets", "sga,sgaa"],
         "unknown preset 'sgaa'"),
        ("presets", ["--tasks", "number-a", "--model", "builtin", "--option", "steps=2"],
         "task 'number-a' has no option 'steps' (its options: none)"),
    ],
)  # fmt: skip
def test_bad_input_is_a_usage_error_naming_the_fix(tmp_path, registered, name, args, fragment):
    result = CliRunner().invoke(load_script(name).main, [*args, "--out-dir", str(tmp_path)])
    assert result.exit_code == 2, result.output
    assert fragment in result.output
    assert not any(tmp_path.iterdir())  # nothing ran


def test_a_folder_run_with_other_settings_is_not_mixed_in(tmp_path, registered):
    method = Method("nudge", "builtin", "cot")
    (cell,) = plan_cells(["number-a"], [method], [0], tmp_path)
    from sga_agent.benchmark.grid import run_cell

    run_cell(cell)
    plan_cells(["number-a"], [method], [0], tmp_path, {"workers": 2})  # neutral: accepted
    with pytest.raises(GridError, match=r"other settings \(epochs: None there, 3 here\)"):
        plan_cells(["number-a"], [method], [0], tmp_path, {"epochs": 3})


def test_methods_override_the_shared_settings(tmp_path, registered):
    methods = [Method("long", "builtin", "quick"), Method("short", "builtin", "quick",
                                                           {"iterations": 1})]  # fmt: skip
    cells = plan_cells(["number-a", "number-b"], methods, [3], tmp_path, {"iterations": 2})
    assert [(c.name, c.config.loop.iterations, c.config.seed) for c in cells] == [
        ("number-a/long/seed-3", 2, 3), ("number-a/short/seed-3", 1, 3),
        ("number-b/long/seed-3", 2, 3), ("number-b/short/seed-3", 1, 3),
    ]  # fmt: skip


def test_an_option_goes_to_the_tasks_that_have_it(tmp_path):
    """The benchmarks page's grid of elastic and homo with --option steps=100: steps reaches
    elastic only; an option no task of the grid has is still refused, named."""
    method = Method("builtin", "builtin", "quick")
    steps = {"steps": "100"}
    elastic, homo = plan_cells(["elastic", "homo"], [method], [0], tmp_path, options=steps)
    assert elastic.config.task_options.steps == 100
    (homo_alone,) = plan_cells(["homo"], [method], [0], tmp_path)
    assert homo.config.task_options == homo_alone.config.task_options
    with pytest.raises(GridError, match="no option 'stepz'"):
        plan_cells(["elastic", "homo"], [method], [0], tmp_path, options={"stepz": "100"})


def test_ranks_tie_and_fewer_valid_seeds_rank_lower():
    grid = {
        "t": {
            "a": Score((1.0, 3.0), 2),
            "b": Score((0.5,), 2),  # lower mean, but one seed found nothing valid
            "c": Score((2.0, 2.0), 2),
            "d": Score((), 2),
        }
    }
    ranks = rank(grid)
    assert ranks == {"t": {"a": 1.5, "c": 1.5, "b": 3.0, "d": 4.0}}
    text = markdown(grid, ranks)
    assert "| t | 2 | **2.00e0 ± 1.41e0** | 5.00e-1 (1/2 seeds) | **2.00e0 ± 0** |" in text
    assert "no valid result |" in text
    assert "| a | 1.5 | 1.50 |" in text
