"""Malformed observations and options of the ``observed`` task are usage errors (exit code 2)
before anything is evaluated; the prompt tells the data, not the material behind it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from sga_agent.cli import main
from sga_agent.options import parse_options
from tasks.observed import ObservedTask
from tasks.observed.options import ObservedOptions
from tests.tasks.observed.conftest import observation_arrays

PLASTIC = ["--option", "searched=plastic", "--option", "E=5e4", "--option", "nu=0.3"]


def write(path: Path, **changes) -> Path:
    arrays = {**observation_arrays(), **changes}
    np.savez(path, **{key: value for key, value in arrays.items() if value is not None})
    return path


def search(registered, tmp_path: Path, observation: Path, *extra: str):
    """``sga-agent search`` on ``observation``; no run folder may appear."""
    out = tmp_path / "runs"
    result = CliRunner().invoke(main, [
        "search", "--task", "observed", "--option", f"observation={observation}", *extra,
        "--model", "builtin", "--out-dir", str(out),
    ])  # fmt: skip
    assert not out.exists() or not any(out.iterdir()), "something ran before the refusal"
    return result


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"positions": np.full((4, 8, 3), np.nan)}, "NaN"),
        ({"positions": np.zeros((4, 8, 2))}, "shape (frames, particles, 3)"),
        ({"times": np.array([1e-3, 2e-3])}, "frames of positions"),
        ({"initial_positions": None}, "lacks ['initial_positions']"),
        ({"dt": None, "walls": None}, "lacks ['dt', 'walls']"),
        ({"particle_indices": np.arange(100, 108)}, "particle_indices must lie"),
    ],
)
def test_a_malformed_observation_is_a_usage_error(
    registered, tmp_path: Path, changes: dict, message: str
) -> None:
    result = search(registered, tmp_path, write(tmp_path / "bad.npz", **changes), *PLASTIC)
    assert result.exit_code == 2, result.output
    assert "option 'observation'" in result.output and message in result.output


def test_a_missing_file_and_missing_options_are_usage_errors(registered, tmp_path: Path) -> None:
    missing = search(registered, tmp_path, tmp_path / "nowhere.npz", *PLASTIC)
    assert missing.exit_code == 2 and "no observation file at" in missing.output
    good = write(tmp_path / "good.npz")
    no_elastic = search(registered, tmp_path, good, "--option", "searched=plastic")
    assert no_elastic.exit_code == 2 and "needs the known elastic law" in no_elastic.output
    bad_nu = search(registered, tmp_path, good, *PLASTIC[:4], "--option", "nu=0.7")
    assert bad_nu.exit_code == 2 and "nu" in bad_nu.output
    family = search(registered, tmp_path, good, *PLASTIC, "--option", "elastic=rubber")
    assert family.exit_code == 2 and "stvk" in family.output
    frames = search(registered, tmp_path, good, *PLASTIC, "--option", "frames=9")
    assert frames.exit_code == 2 and "option 'frames' must lie in [2, 4]" in frames.output
    budget = search(registered, tmp_path, good, *PLASTIC, "--option", "graph_memory_mb=0")
    assert budget.exit_code == 2 and "option 'graph_memory_mb' must be a positive" in budget.output


def test_options_are_typed_with_the_path_made_absolute(tmp_path: Path, monkeypatch) -> None:
    write(tmp_path / "obs.npz")
    monkeypatch.chdir(tmp_path)
    raw = {"observation": "obs.npz", "searched": "plastic", "E": "5e4", "nu": "0.3",
           "segment": "20", "graph_memory_mb": "64"}  # fmt: skip
    options = parse_options(ObservedTask.options_type, raw, "observed")
    assert isinstance(options, ObservedOptions)
    assert options.observation == str(tmp_path / "obs.npz")
    assert options.E == 5e4 and options.segment == 20 and options.elastic == "stvk"
    assert options.graph_memory_mb == 64


def test_the_prompt_describes_the_data_and_no_truth(tmp_path: Path) -> None:
    path = write(tmp_path / "obs.npz")
    (tmp_path / "obs.truth.json").write_text(
        '{"family": "vonmises", "parameters": {"E": 5e4, "nu": 0.3, "yield_stress": 777}}'
    )
    task = ObservedTask().with_options(ObservedOptions(str(path), "plastic", E=5e4, nu=0.3))
    context = task.prompt_parts().context
    assert "8 of the 27 points at 4 moments" in context
    assert "no teacher forcing" in context and "Young's modulus 50000 Pa" in context
    assert "777" not in context and "von Mises" not in context
    assert "return F" in task.seed_solution()
    elastic = ObservedTask().with_options(ObservedOptions(str(path), "elastic"))
    assert "Kirchhoff" in elastic.prompt_parts().context
    assert "log_youngs_modulus" in elastic.seed_solution()
