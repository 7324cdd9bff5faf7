"""``sga-agent report`` on a run folder written by the search with test doubles (no simulator)."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
from click.testing import CliRunner

from sga_agent.cli import main
from sga_agent.report import pictures
from sga_agent.report.data import Candidate, Run
from sga_agent.report.plots import DPI, curves_size
from sga_agent.run_store import RunStore
from sga_agent.search import Search
from sga_agent.task import Evaluation
from tests.sga_agent.test_search import LAW, FakeTask, LossInCode, Scripted, config


class CurvesAndFailures(LossInCode):
    """The loss double, plus inner-loop curves, and an unstable outcome for loss 7."""

    def submit(self, task, solution, settings):
        future = super().submit(task, solution, settings)
        loss = future.result().loss
        if loss == 7.0:
            future._result = Evaluation.invalid("blew up", status="unstable")
        else:
            future._result.parameters = {"scale": loss / 2}
            future._result.curves = {"loss": [2 * loss, loss], "scale": [1.0, loss / 2]}
        return future


def png_size(path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


def test_report_has_every_section_and_figure(tmp_path):
    cfg = config()
    store = RunStore.create(tmp_path, cfg, {"proposer": "scripted"})
    store.append({"type": "sandbox", "isolation": {"network": "none", "filesystem": "landlock"}})
    answers = [LAW.format(value=v) for v in (5.0, 3.0, 7.0, 1.0, 2.0, 4.0)]
    Search(cfg, FakeTask(), Scripted(answers), CurvesAndFailures(), store).run()

    result = CliRunner().invoke(main, ["report", str(store.path), "--no-motion"])
    assert result.exit_code == 0, result.output
    folder = store.path / "report"
    assert str(folder / "report.md") in result.output
    md = (folder / "report.md").read_text()
    page = (folder / "report.html").read_text()
    for title in ("Summary", "Best loss per iteration", "Outcomes per iteration",
                  "Inner-loop curves of the top 3 candidates", "Best solution"):  # fmt: skip
        assert f"## {title}" in md and f"<h2>{title}</h2>" in page
    assert "landlock" in md and "scripted" in md and "90" in md  # isolation, proposer, tokens
    assert "**1** (02-exploit-00)" in md and "F * 1.0" in md and "feedback for loss 1.0" in md
    assert "| 1 | 2 | 0 | 0 | 1 | 0 | 0 | 0 | 3 |" in md  # iteration 1: 2 ok, 1 unstable
    for name in ("best_loss.png", "outcomes.png", "curves.png"):
        assert f'<img src="{name}"' in page and f"]({name})" in md
    assert png_size(folder / "best_loss.png") == (7 * DPI, 4 * DPI)
    assert png_size(folder / "outcomes.png") == (7 * DPI, 4 * DPI)
    width, height = curves_size([None] * 3)
    assert png_size(folder / "curves.png") == (round(width * DPI), round(height * DPI))


class WithMolecules(CurvesAndFailures):
    """As :class:`CurvesAndFailures`, each scored candidate recorded as a molecule."""

    SMILES = {100.0: "CCCCCCCCO", 5.0: "c1ccccc1O", 3.0: "CC(=O)Nc1ccc(O)cc1", 1.0: "CCOC(=O)C",
              2.0: "c1ccc2ccccc2c1", 4.0: "CCN(CC)CC"}  # fmt: skip

    def submit(self, task, solution, settings):
        future = super().submit(task, solution, settings)
        if future.result().valid:
            future._result.extras["smiles"] = self.SMILES[future.result().loss]
        return future


def test_molecule_report_draws_the_top_three(tmp_path):
    cfg = config(task="homo")  # a registered molecule task: the report adds its picture
    store = RunStore.create(tmp_path, cfg, {"proposer": "scripted"})
    answers = [LAW.format(value=v) for v in (5.0, 3.0, 7.0, 1.0, 2.0, 4.0)]
    Search(cfg, FakeTask(), Scripted(answers), WithMolecules(), store).run()

    result = CliRunner().invoke(main, ["report", str(store.path)])
    assert result.exit_code == 0, result.output
    folder = store.path / "report"
    assert "## Top 3 molecules" in (folder / "report.md").read_text()
    assert '<img src="molecules.png"' in (folder / "report.html").read_text()
    assert png_size(folder / "molecules.png") == (3 * 450, 400)  # three 450x400 drawings
    said = result.stderr.splitlines()  # what each slow step is doing, before it starts
    assert said[0] == f"reading the run in {store.path}..."
    assert said[1:] == ["plotting the losses...", "drawing the top molecules..."]


@pytest.mark.slow
def test_motion_picture_is_drawn_from_the_fit_artifact_never_from_code(tmp_path):
    from tasks.constitutive.artifacts import encode_positions
    from tasks.constitutive.evaluation import ensure_runtime, ground_truth
    from tasks.constitutive.specs import SPECS

    ensure_runtime("float32")
    observed = ground_truth(SPECS["elastic"], 12).positions
    folder = tmp_path / "01-exploit-00"
    folder.mkdir()
    shifted = observed + np.array([0.05, 0.0, 0.0])
    artifact = {"trajectory": encode_positions(shifted, frames=4)}
    (folder / "artifacts.json").write_text(json.dumps(artifact))
    code = "raise SystemExit('a report must never run candidate code')\n"
    best = Candidate("01-exploit-00", "ok", 1e-3, code=code, folder=folder)
    run = Run(tmp_path, {"task": "elastic", "task_options": {"steps": 12}}, [best])
    steps, truth, fitted = pictures.best_motion(run, best)
    assert steps.tolist() == [0, 4, 8, 12]
    assert np.abs(fitted - shifted[steps]).max() < 1e-5  # 16-bit quantisation over the box
    assert np.array_equal(truth, observed[steps])
    png, gif = pictures.plot_motion(run, best, tmp_path)
    assert png_size(png) == (round(2.8 * pictures.MOTION_FRAMES * DPI), 6 * DPI)
    assert gif.read_bytes()[:6] == b"GIF89a"


def test_report_rejects_a_folder_that_is_no_run(tmp_path):
    result = CliRunner().invoke(main, ["report", str(tmp_path)])
    assert result.exit_code == 2 and "not a run folder" in result.output
