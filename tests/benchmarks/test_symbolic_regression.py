"""``benchmarks/symbolic_regression.py --quick`` end to end: the SR fits whose libraries are
installed (the ``sr`` extra), the true law and a built-in GP search, scored on the same samples
and put back into the simulator."""

from __future__ import annotations

import importlib.util
import json
import math
import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest

REPO = Path(__file__).resolve().parents[2]
#: method of the script -> the library it needs
pytestmark = pytest.mark.slow  # the quick benchmark runs a search and three fits: a minute

LIBRARIES = {"operon": "pyoperon", "ffx": "ffx", "mlp": "sklearn"}
NAMES = {"operon": "Operon", "ffx": "FFX", "mlp": "MLP"}
HEADER = "| method | symbolic | R² ↑ | MSE ↓ | MAE ↓ | trajectory loss ↓ | fit (s) |"


def installed() -> list[str]:
    return [method for method, module in LIBRARIES.items() if importlib.util.find_spec(module)]


def load_script() -> ModuleType:
    spec = importlib.util.spec_from_file_location(
        "bench_symbolic_regression", REPO / "benchmarks" / "symbolic_regression.py"
    )
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def quick(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, dict]:
    """One ``--quick`` run with the installed methods: (table.md, results.json)."""
    out = tmp_path_factory.mktemp("sr")
    path = os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))
    env = {**os.environ, "PYTHONPATH": path, "LITELLM_LOCAL_MODEL_COST_MAP": "True"}
    command = [sys.executable, str(REPO / "benchmarks" / "symbolic_regression.py"), "--quick",
               "--methods", ",".join(installed()), "--out-dir", str(out)]  # fmt: skip
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    table = (out / "table.md").read_text()
    assert done.stdout.endswith(table)  # the printed table is the written one
    return table, json.loads((out / "results.json").read_text())


def rows_by_method(results: dict) -> dict[str, dict]:
    return {row["method"]: row for row in results["rows"]}


def test_table_has_a_line_per_method(quick: tuple[str, dict]) -> None:
    table, results = quick
    lines = table.splitlines()
    assert lines[0] == HEADER and lines[1] == "|---|---|---|---|---|---|---|"
    names = [line.split(" | ")[0].removeprefix("| ") for line in lines[2:]]
    expected = ["neo-Hookean (ground truth)", *(NAMES[m] for m in installed()),
                "sga-agent search (builtin)"]  # fmt: skip
    assert names == expected == [row["method"] for row in results["rows"]]
    assert all(line.count("|") == 8 for line in lines)
    assert results["samples"]["train"] + results["samples"]["test"] == results["budget"]["samples"]


def test_true_law_fits_its_own_samples_exactly(quick: tuple[str, dict]) -> None:
    """R2 of the ground truth on its own stresses is 1, and in the simulator it reproduces the
    ground-truth trajectory (the Taichi law it mirrors) to round-off."""
    truth = rows_by_method(quick[1])["neo-Hookean (ground truth)"]
    assert truth["r2"] == 1.0 and truth["mse"] == 0.0 and truth["mae"] == 0.0
    assert truth["trajectory"] == "ok" and 0 <= truth["trajectory_loss"] < 1e-12


def test_search_law_is_rebuilt_with_its_fitted_parameters(quick: tuple[str, dict]) -> None:
    """Scored again with zero epochs on the same scene, the best law gives the loss the search
    recorded for it: the graph was rebuilt and its fitted parameters loaded."""
    row = rows_by_method(quick[1])["sga-agent search (builtin)"]
    assert row["trajectory"] == "ok"
    assert row["trajectory_loss"] == pytest.approx(row["notes"]["recorded_loss"], rel=1e-3)
    assert row["notes"]["parameters"] and row["notes"]["task_options"]["steps"] == 200
    assert all(math.isfinite(row[key]) for key in ("r2", "mse", "mae"))


@pytest.mark.parametrize("method", list(LIBRARIES))
def test_regressor_row(method: str, quick: tuple[str, dict]) -> None:
    """Scores finite where the predictions are, the torch law equal to the library's own
    predictions, and a trajectory that is either scored or reported unstable."""
    pytest.importorskip(LIBRARIES[method], reason=f"needs the sr extra ({LIBRARIES[method]})")
    row = rows_by_method(quick[1])[NAMES[method]]
    assert row["non_finite"] == 0, "the quick fits predict finite stresses on the test split"
    assert math.isfinite(row["r2"]) and row["r2"] <= 1.0
    assert row["mse"] > 0 and row["mae"] > 0 and math.isfinite(row["fit_seconds"])
    assert row["torch_error"] < 1e-2  # Operon predicts in float32, the torch law in float64
    assert len(row["expressions"]) == (9 if row["symbolic"] else 0)
    if row["trajectory"] == "ok":
        assert math.isfinite(row["trajectory_loss"]) and row["trajectory_loss"] > 0
    else:
        assert row["trajectory"].startswith("unstable"), row["trajectory"]


def test_expressions_become_torch_functions_without_running_them() -> None:
    """Operon's infix text is translated node by node; anything else is refused."""
    import torch

    script = load_script()
    x = [torch.full((2,), 2.0, dtype=torch.float64) for _ in range(9)]
    names = {f"X{i + 1}": i for i in range(9)}
    function = script.expression_function("((-1.5) + (2.0 * log((X1 ^ 2))))", names)
    expected = torch.full((2,), -1.5 + 2.0 * math.log(4.0), dtype=torch.float64)
    assert torch.allclose(function(x), expected)
    for text in ("__import__('os').getcwd()", "X1.real", "eval('1')", "X10 + 1", "[X1][0]"):
        with pytest.raises(ValueError, match="unsupported"):
            script.expression_function(text, names)
