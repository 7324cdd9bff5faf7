"""End to end: `sga-agent evaluate` on molecule files, a batch of drugs, the calibration script."""

from __future__ import annotations

import importlib.util
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from sga_agent.task import EvaluationSettings
from tasks.molecules import HomoTask
from tasks.molecules.calibration import CALIBRATION, QM9_STATISTICS
from tasks.molecules.examples import DRUG_LIKE
from tests.tasks.molecules.helpers import score, solution_for

ROOT = Path(__file__).resolve().parents[3]


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "sga_agent", "evaluate", *args],
        capture_output=True,
        text=True,
        timeout=600,
    )


@pytest.mark.slow
def test_cli_evaluates_a_molecule_answer(tmp_path: Path) -> None:
    answer = tmp_path / "answer.md"
    answer.write_text("### Code\n```python\n" + HomoTask().seed_solution() + "```\n")
    run = _cli("--task", "homo", "--epochs", "1", "--json", str(answer))
    assert run.returncode == 0, run.stderr
    evaluation = json.loads(run.stdout)
    assert evaluation["valid"] and evaluation["extras"]["smiles"] == "CC(=O)Nc1ccc(O)cc1"
    assert len(evaluation["curves"]["loss"]) == 2


def test_cli_reports_an_invalid_molecule(tmp_path: Path) -> None:
    molecule = tmp_path / "molecule.py"
    molecule.write_text('SMILES = "CCCCCCCC.O"\ncoordinates = [[0, 0, 0]]\n')
    run = _cli("--task", "gap-low", str(molecule))
    assert run.returncode == 1
    lines = [line for line in run.stderr.splitlines() if line.startswith("invalid:")]
    assert len(lines) == 1 and "fragments" in lines[0], run.stderr
    assert "Traceback" not in run.stderr + run.stdout


@pytest.mark.heavy
def test_twenty_drug_like_molecules_evaluate() -> None:
    assert len(DRUG_LIKE) == 20
    task = HomoTask()
    for name, smiles in DRUG_LIKE.items():
        evaluation = score(task, solution_for(smiles), EvaluationSettings(epochs=2))
        assert evaluation.valid, (name, evaluation.reason)
        assert evaluation.extras["geometry_source"] == "proposal", name


@pytest.mark.heavy
@pytest.mark.skipif(importlib.util.find_spec("qm9pack") is None, reason="qm9pack not installed")
def test_calibration_script_on_a_sample_agrees_with_the_shipped_fit() -> None:
    script = ROOT / "scripts" / "calibrate_qm9.py"
    run = subprocess.run(
        [sys.executable, str(script), "--limit", "400", "--workers", "1"],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert run.returncode == 0, run.stderr
    for prop, stats in QM9_STATISTICS.items():
        line = re.search(rf"^  {prop}\s+mean ([-+.\d]+) Ha, std ([.\d]+) Ha", run.stdout, re.M)
        assert line, run.stdout
        assert float(line[1]) == pytest.approx(stats.mean, abs=1e-6)
        assert float(line[2]) == pytest.approx(stats.std, abs=1e-6)
        fit = re.search(
            rf"^  {prop}\s+slope ([.\d]+) intercept ([-+.\d]+).*test ([.\d]+) \|", run.stdout, re.M
        )
        assert fit, run.stdout
        assert float(fit[3]) > 0.8  # held-out correlation
        # A 400-molecule sample gives the shipped line up to sampling noise.
        diff = re.search(rf"^  {prop}\s+shipped .* std \(allowed .*\) -> (\w+)$", run.stdout, re.M)
        assert diff and diff[1] == "agree", run.stdout
        assert CALIBRATION[prop].r_test > 0.85
