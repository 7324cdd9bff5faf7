"""``sga-agent report`` on a run folder written by the search with test doubles (no simulator)."""

from __future__ import annotations

import contextlib
import io
import json
import re
import struct
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from rich.console import Console

from sga_agent.cli import main
from sga_agent.config import PRESETS
from sga_agent.heap import ranked_loss
from sga_agent.report.data import Candidate, read_run
from sga_agent.report.plots import DPI, curves_figure, curves_size, outcomes_figure
from sga_agent.report.render import Section, Text, markdown, to_html
from sga_agent.run_store import RunStore
from sga_agent.search import Search, SearchResult
from sga_agent.task import (
    STATUSES,
    Assessment,
    Evaluation,
    Probe,
    Simplified,
    as_task,
    compared,
    within_noise,
)
from tests.sga_agent.test_fidelity import TwoFidelities
from tests.sga_agent.test_fidelity import config as fidelity_config
from tests.sga_agent.test_fidelity import law as fidelity_law
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
    titles = ["Summary", "Bilevel optimisation", "Best loss against evaluations and wall time",
              "Best loss per iteration", "Inner-loop curves of the top 3 distinct solutions",
              "Outcomes per iteration", "Candidates"]  # fmt: skip
    assert [line[3:] for line in md.splitlines() if line.startswith("## ")] == titles
    for title in titles:
        assert f"<h2>{title}</h2>" in page
    folded = ["Settings", "Isolation of the evaluation workers",
              "Feedback of the best solution (02-exploit-00), as proposers saw it"]  # fmt: skip
    folds = "<summary><b>"  # a folded section's (a candidate's row folds its own texts too)
    assert md.count(folds) == page.count(folds) == len(folded)
    for title in folded:  # the records come last, folded away
        assert f"<summary><b>{title}</b></summary>" in md.split("## Candidates")[1]
    assert "landlock" in md and "scripted" in md and "90 tokens" in md
    assert "**1** (02-exploit-00), **100x below** the seed's 100" in md
    assert "F * 1.0" in md and "feedback for loss 1.0" in md
    assert "| 1 | 2 | 0 | 0 | 1 | 0 | 0 | 0 | 3 |" in md  # iteration 1: 2 ok, 1 unstable
    assert "- 7 evaluations (6 ok, 1 unstable) in " in md  # as the end screen counts them
    assert "screen" not in md.split("## Feedback")[0].lower()  # no screens: none of their parts
    for name in ("zigzag.png", "progress.png", "best_loss.png", "outcomes.png", "curves.png"):
        assert f'<img src="{name}"' in page and f"]({name})" in md
    assert png_size(folder / "zigzag.png") == (9 * DPI, round(4.2 * DPI))
    assert png_size(folder / "progress.png") == (11 * DPI, 4 * DPI)
    assert png_size(folder / "best_loss.png") == (7 * DPI, 4 * DPI)
    assert png_size(folder / "outcomes.png") == (7 * DPI, 4 * DPI)
    width, height = curves_size([None] * 3)
    assert png_size(folder / "curves.png") == (round(width * DPI), round(height * DPI))


def list_items(md: str) -> list[str]:
    """The Markdown's list items, not counting lines of code blocks (the feedback's)."""
    items, fenced = [], False
    for line in md.splitlines():
        if line.startswith("```"):
            fenced = not fenced
        elif line.startswith("- ") and not fenced:
            items.append(line[2:])
    return items


def test_a_list_after_a_line_of_text_renders_as_a_list():
    """The fitted-parameter list follows its heading line in one text block: in HTML it is a
    <ul>, in Markdown it gets the blank line a list needs."""
    text = "What its fitted parameters amount to:\n- `exp(log_E)` = 2e+05\n- `nu` = 0.3\nafter"
    sections = [Section("Summary", [Text(text), Text("- one\n- two")])]
    page = to_html("t", sections)
    assert (
        "<p>What its fitted parameters amount to:</p><ul><li><code>exp(log_E)</code> = 2e+05</li>"
        "<li><code>nu</code> = 0.3</li></ul><p>after</p>"
    ) in page.replace("\n", "")
    assert "<ul><li>one</li><li>two</li></ul>" in page
    md = markdown("t", sections)
    assert "amount to:\n\n- `exp(log_E)` = 2e+05\n- `nu` = 0.3\n\nafter\n" in md
    assert page.count("<li>") == len(list_items(md)) == 4


class WithMolecules(CurvesAndFailures):
    """As :class:`CurvesAndFailures`, each scored candidate recorded as a molecule whose
    normalized HOMO is its loss's square root below the target 0, as the homo task records."""

    SMILES = {100.0: "CCCCCCCCO", 5.0: "c1ccccc1O", 3.0: "CC(=O)Nc1ccc(O)cc1", 1.0: "CCOC(=O)C",
              2.0: "c1ccc2ccccc2c1", 4.0: "CCN(CC)CC"}  # fmt: skip

    def submit(self, task, solution, settings):
        future = super().submit(task, solution, settings)
        result = future.result()
        if result.valid:
            result.extras.update(smiles=self.SMILES[result.loss], target=0.0, property_name="HOMO")
            result.parameters["property"] = -(result.loss**0.5)
        return future


def test_molecule_report_draws_the_top_three(tmp_path):
    cfg = config(task="homo")  # a registered molecule task: the report adds its picture
    store = RunStore.create(tmp_path, cfg, {"proposer": "scripted"})
    answers = [LAW.format(value=v) for v in (5.0, 3.0, 7.0, 1.0, 2.0, 4.0)]
    Search(cfg, FakeTask(), Scripted(answers), WithMolecules(), store).run()

    result = CliRunner().invoke(main, ["report", str(store.path)])
    assert result.exit_code == 0, result.output
    folder = store.path / "report"
    md = (folder / "report.md").read_text()
    assert "## Top 3 molecules" in md
    # the best, 1.0: normalized HOMO -1, i.e. QM9 mean - 1 std = -0.2622 Ha, 1 from the target
    assert "| 1 | 02-exploit-00 | CCOC(=O)C | -1.000 | -0.2622 Ha (-7.13 eV) | +0 | 1 | 1 |" in md
    assert '<img src="molecules.png"' in (folder / "report.html").read_text()
    assert png_size(folder / "molecules.png") == (3 * 450, 400)  # three 450x400 drawings
    said = result.stderr.splitlines()  # what each slow step is doing, before it starts
    assert said[0] == f"reading the run in {store.path}..."
    assert said[1:] == ["plotting the losses...", "drawing the top molecules..."]


def test_report_rejects_a_folder_that_is_no_run(tmp_path):
    result = CliRunner().invoke(main, ["report", str(tmp_path)])
    assert result.exit_code == 2 and "not a run folder" in result.output


def _fitted_defaults(code: str) -> dict[str, float]:
    """``name: float = VALUE`` of the law's ``__init__``."""
    return {name: float(value) for name, value in re.findall(r"(\w+): float = ([-+.\deE]+)", code)}


def _free_run_errors(code: str, steps: int) -> tuple[float, float]:
    """The RMS position error (in body sizes) at the end and on average of the elastic law in
    ``code`` (our own GP's output, run here on purpose) simulated from the initial state."""
    import torch

    import taichi_mpm as tm
    from bridges.laws import NoPlasticity
    from bridges.rollout import Rollout
    from tasks.constitutive.evaluation import ground_truth
    from tasks.constitutive.specs import SPECS

    namespace: dict = {}
    exec(compile(code, "best_law.py", "exec"), namespace)  # noqa: S102 - a test, our own law
    law = namespace["Physics"]().to(torch.float32).requires_grad_(False)
    observed = ground_truth(SPECS["elastic"], steps).positions
    simulated = Rollout(tm.paper_scene(steps=steps), NoPlasticity(), law).simulate()
    size = np.ptp(observed[0], axis=0).max()
    errors = np.sqrt(((simulated - observed) ** 2).sum(-1).mean(-1)) / size
    return float(errors[-1]), float(errors.mean())


@pytest.mark.slow
def test_report_of_a_real_search_states_the_run_s_numbers(tmp_path):
    """A short real search (built-in GP, sandboxed workers, a 200-step scene: two
    teacher-forced segments), then its report: every number of the summary is checked
    against the run folder or computed again here by another route."""
    from sga_agent.registry import load_task
    from sga_agent.task import EvaluationSettings
    from tasks.constitutive.evaluation import ensure_runtime
    from tasks.constitutive.options import ConstitutiveOptions
    from tasks.constitutive.report import MOTION_FRAMES

    ensure_runtime("float32")
    steps = 200
    search = CliRunner().invoke(main, [
        "search", "--task", "elastic", "--option", f"steps={steps}", "--iterations", "1",
        "--exploit", "1", "--explore", "1", "--epochs", "2", "--workers", "2",
        "--fidelity", "full", "--out-dir", str(tmp_path), "--json",
    ])  # fmt: skip
    assert search.exit_code == 0, search.output
    run_dir = Path(json.loads(search.stdout)["run"])  # nothing but the JSON on stdout
    result = CliRunner().invoke(main, ["report", str(run_dir), "--json"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)  # nothing but the JSON on stdout
    found = report["findings"]
    evaluation = {
        folder.name: json.loads((folder / "evaluation.json").read_text())
        for folder in (run_dir / "candidates").iterdir()
    }
    best = found["best"]["candidate"]

    # seed, best and their ratio, as recorded
    assert found["seed"]["loss"] == evaluation["00-seed"]["loss"]
    parsimony = json.loads((run_dir / "config.json").read_text())["config"]["loop"]["parsimony"]
    assert parsimony == PRESETS["quick"]["parsimony"]
    valid = [e for e in evaluation.values() if e["valid"]]
    ranked = min(valid, key=lambda e: ranked_loss(e["loss"], len(e["parameters"]), parsimony))
    assert found["best"]["loss"] == ranked["loss"]
    assert found["seed_over_best"] == pytest.approx(found["seed"]["loss"] / found["best"]["loss"])
    # the true law: examples/laws/neo_hookean.py captured and scored unfitted, here
    task = load_task("elastic")
    truth_code = (Path(__file__).parents[2] / "examples/laws/neo_hookean.py").read_text()
    settings = EvaluationSettings(epochs=0, options=ConstitutiveOptions(steps=steps))
    truth = task.evaluate(task.capture(truth_code), settings)
    assert found["truth"] == "neo-Hookean, E = e^13 Pa, nu = 0.245"
    assert found["truth_loss"] < 1e-12 and truth.loss < 1e-12  # float32 noise, both
    assert found["truth_loss"] == pytest.approx(truth.loss, rel=0.5)
    assert found["best_over_truth"] == pytest.approx(found["best"]["loss"] / found["truth_loss"])
    # the law shown carries the fitted constants
    shown = _fitted_defaults(found["best_solution"])
    fitted = evaluation[best]["parameters"]
    assert fitted and set(fitted) <= set(shown)
    for name, value in fitted.items():
        assert shown[name] == pytest.approx(value, rel=1e-7)
    # the free run, simulated here from the code shown
    final, mean = _free_run_errors(found["best_solution"], steps)
    free = found["free_run"]
    assert free["steps"] == steps and free["body_size"] == pytest.approx(0.45, rel=1e-6)
    assert free["final_error"] == pytest.approx(final, rel=1e-3)
    assert free["mean_error"] == pytest.approx(mean, rel=1e-3)
    # the search wrote the same findings into summary.json
    summary = json.loads((run_dir / "summary.json").read_text())
    for key in ("seed", "best", "truth", "truth_loss", "best_solution", "free_run", "held_out",
                "verdict"):
        assert summary["findings"][key] == found[key], key
    # the held-out scene (120 steps for a 200-step training scene) and the verdict on it
    held_out = found["held_out"]
    assert held_out["scene"] == "held-out scene" and held_out["steps"] == 120
    assert free["scene"] == "training scene"
    assert f"{100 * held_out['final_error']:.2g} % free-run error on the held-out" in found[
        "verdict"]  # fmt: skip
    assert json.loads((run_dir / "provenance.json").read_text()) == {"truth": found["truth"]}
    assert found["changed_since_start"] == []
    assert summary["best"]["candidate"] == best  # the existing keys stay
    # the pages state them, and the pictures have their sizes
    md = (run_dir / "report" / "report.md").read_text()
    summary_part = md.split("## Free run")[0]
    assert f"**{found['best']['loss']:.4g}** ({best})" in summary_part
    assert f"the seed's {found['seed']['loss']:.4g}" in summary_part
    assert f"the true law's: {found['truth_loss']:.4g}" in summary_part
    assert f"**{100 * free['final_error']:.3g}%** of the body size" in summary_part
    assert f"**{100 * held_out['final_error']:.3g}%** of the body size" in summary_part
    assert f"- **verdict**: {found['verdict']}" in summary_part
    assert found["best_solution"].strip() in summary_part
    folder = run_dir / "report"
    page = (folder / "report.html").read_text()
    assert "amount to (computed from the captured graph):\n\n- `" in md
    assert page.count("<li>") == len(list_items(md))  # each list, the derived values too
    assert png_size(folder / "motion.png") == (round(2.8 * MOTION_FRAMES * DPI), 6 * DPI)
    assert png_size(folder / "zigzag.png") == (9 * DPI, round(4.2 * DPI))
    assert (folder / "motion.gif").read_bytes()[:6] == b"GIF89a"
    assert png_size(folder / "motion-held-out.png") == png_size(folder / "motion.png")
    assert (folder / "motion-held-out.gif").read_bytes()[:6] == b"GIF89a"


def test_derived_values_are_read_from_the_captured_graph():
    """Parameters behind a transform are shown with what they amount to, computed from the
    captured graph's own operations; expressions mixing two parameters or F are not."""
    from sga_agent.registry import load_task
    from tasks.constitutive.assessment import derived_values

    code = '''import torch
import torch.nn as nn


class Physics(nn.Module):
    def __init__(self, log_e: float = 10.0, nu_logit: float = 0.0):
        super().__init__()
        self.log_e = nn.Parameter(torch.tensor(log_e))
        self.nu_logit = nn.Parameter(torch.tensor(nu_logit))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        E = torch.exp(self.log_e)
        nu = 0.49 * torch.sigmoid(self.nu_logit)
        return E / (1 + nu) * (F - torch.eye(3, dtype=F.dtype))
'''
    graph = load_task("elastic").capture(code)["law"]
    derived = derived_values(graph, {"log_e": 13.0, "nu_logit": 0.5})
    assert derived.keys() == {"exp(log_e)", "(sigmoid(nu_logit) * 0.49)"}
    assert derived["exp(log_e)"] == pytest.approx(np.exp(13.0))
    assert derived["(sigmoid(nu_logit) * 0.49)"] == pytest.approx(0.49 / (1 + np.exp(-0.5)))


def test_the_runner_adds_the_findings_the_search_core_leaves_out(tmp_path):
    """The search writes its totals to summary.json and knows nothing of findings; the runner
    then adds them, read back from the run folder as the report reads them."""
    from sga_agent.runner import record_findings

    cfg = config()
    store = RunStore.create(tmp_path, cfg, {"proposer": "scripted"})
    answers = [LAW.format(value=v) for v in (5.0, 3.0, 7.0, 1.0, 2.0, 4.0)]
    Search(cfg, FakeTask(), Scripted(answers), CurvesAndFailures(), store).run()
    totals = store.summary()
    assert "findings" not in totals and totals["best"]["candidate"] == "02-exploit-00"

    record_findings(store, FakeTask(), cfg.task_options)
    summary = store.summary()
    assert {key: summary[key] for key in totals} == totals  # the totals stay as they were
    findings = summary["findings"]
    assert findings["best"] == {"candidate": "02-exploit-00", "loss": 1.0, "status": "ok"}
    assert findings["seed"]["loss"] == 100.0 and findings["seed_over_best"] == 100.0
    assert findings["truth"] is None and findings["free_run"] is None  # FakeTask assesses nothing
    assert findings["molecules"] == []


class _Run:
    """A free run's record, as a task's assessment holds one."""

    def __init__(self, error: float) -> None:
        self.error = error

    def to_dict(self) -> dict:
        return {"final_error": self.error, "scene": "held-out scene"}


def run_through_the_runner(
    tmp_path, monkeypatch, task, values, evaluator=None, **settings
) -> tuple[RunStore, SearchResult]:
    """A search of ``task`` run as the CLI runs it (findings and provenance included), its
    answers the fake laws of ``values``, scored by the loss written in their code (by
    ``evaluator``, default :class:`LossInCode`); ``settings`` override the search's."""
    from sga_agent import runner

    cfg = config(**settings)
    store = RunStore.create(tmp_path, cfg, {"proposer": "scripted"})
    pool = contextlib.nullcontext(evaluator or LossInCode())
    monkeypatch.setattr(runner, "make_pool", lambda config: pool)
    monkeypatch.setattr(runner, "pool_record", lambda pool: {"type": "sandbox"})
    answers = [LAW.format(value=v) for v in values]
    return store, runner.run(cfg, store, proposer=Scripted(answers), task=task)


class MeasuredTask(FakeTask):
    """A task that records what it is measured against (a file's hash) and assesses with
    what was recorded: the double of a task whose observation file can change."""

    digest = "aaaa"

    def provenance(self, options) -> dict:
        return {"observation_sha256": self.digest}

    def with_provenance(self, recorded):
        task = MeasuredTask()
        task.digest = recorded["observation_sha256"]
        return task

    def assess(self, artifacts, parameters, options, simulate):
        return Assessment(truth=f"the truth of {self.digest}", held_out=_Run(0.25),
                          verdict="the best law does not reproduce the motion")  # fmt: skip


def test_a_report_says_what_changed_since_the_run_started(tmp_path, monkeypatch):
    """The runner records the task's provenance when the search starts; the findings hand
    it back to the task (``with_provenance``) and list what differs from the task's now; the
    held-out record and the verdict reach summary.json and the report."""

    store, _ = run_through_the_runner(tmp_path, monkeypatch, MeasuredTask(),
                                      (5.0, 3.0, 7.0, 1.0, 2.0, 4.0))  # fmt: skip
    assert store.provenance() == {"observation_sha256": "aaaa"}
    findings = store.summary()["findings"]
    assert findings["held_out"] == {"final_error": 0.25, "scene": "held-out scene"}
    assert findings["verdict"] == "the best law does not reproduce the motion"
    assert findings["changed_since_start"] == []

    monkeypatch.setattr(MeasuredTask, "digest", "bbbb")  # the file was rewritten since
    monkeypatch.setattr("sga_agent.report.build.load_or_none",
                        lambda name: as_task(MeasuredTask()))  # fmt: skip
    result = CliRunner().invoke(main, ["report", str(store.path), "--json"])
    assert result.exit_code == 0, result.output
    found = json.loads(result.stdout)["findings"]
    assert found["truth"] == "the truth of aaaa"  # the recorded one, handed back to the task
    assert found["changed_since_start"] == ['observation_sha256: "aaaa" at the start, "bbbb" now']
    md = (store.path / "report" / "report.md").read_text()
    assert "- **verdict**: the best law does not reproduce the motion" in md
    assert '**changed since the run started** (this report names what the run recorded ' \
        'then): observation_sha256: "aaaa" at the start, "bbbb" now' in md  # fmt: skip


class ComparingTask(MeasuredTask):
    """A task that compares the forms it is handed as a simulation task would: those within
    twice the best loss part by 9 % under its one probe."""

    handed: list = []

    def with_provenance(self, recorded):
        return self

    def compare_forms(self, candidates, options, folder):
        ComparingTask.handed = [(c.id, c.loss) for c in candidates]
        losses = [c.loss for c in candidates]
        band = within_noise(losses)
        probe = Probe("an impact", "the body thrown down", str(folder / "probes" / "impact.npz"))
        spreads = {"an impact": 0.09} if sum(loss <= band for loss in losses) > 1 else {}
        return compared([c.id for c in candidates], losses, band, spreads,
                        {"an impact": probe}, 0.05)  # fmt: skip

    def simplify(self, candidate, options):
        return Simplified(f"# {candidate.id}, simpler\n", ["its second term"], 1.2, 1.0, 2.0)


def test_the_forms_that_fit_equally_and_the_probe_reach_the_summary_and_the_report(
    tmp_path, monkeypatch
):
    """The task is handed the run's distinct scored forms, best first; what it finds goes
    into summary.json and the report's summary, in words."""

    store, _ = run_through_the_runner(tmp_path, monkeypatch, ComparingTask(),
                                      (5.0, 3.0, 7.0, 1.0, 1.5, 4.0))  # fmt: skip
    assert [loss for _, loss in ComparingTask.handed] == [1.0, 1.5, 3.0, 4.0, 5.0, 7.0]
    found = store.summary()["findings"]["identifiability"]
    assert found["determined"] is False and found["losses"] == [1.0, 1.5]
    assert found["probe"]["file"] == str(store.path / "probes" / "impact.npz")
    assert found["sentence"].startswith("the observation does not determine the law: 2 "
                                        "distinct forms fit it")  # fmt: skip
    monkeypatch.setattr("sga_agent.report.build.load_or_none",
                        lambda name: as_task(ComparingTask()))  # fmt: skip
    result = CliRunner().invoke(main, ["report", str(store.path)])
    assert result.exit_code == 0, result.output
    md = (store.path / "report" / "report.md").read_text()
    assert f"- **identifiability**: {found['sentence']}" in md
    simplified = store.summary()["findings"]["simplified"]
    assert simplified["solution"] == "# 02-exploit-00, simpler\n"  # the best's
    assert ("Simplified: 1 of its parts costs less than the noise and is dropped (its second "
            "term): the loss goes from 1 to 1.2, 2 at most.\n\n```python\n# 02-exploit-00, "
            "simpler\n```") in md  # fmt: skip


class SlowLossInCode(LossInCode):
    """:class:`LossInCode` taking 0.2 s an evaluation."""

    def submit(self, task, solution, settings):
        time.sleep(0.2)
        return super().submit(task, solution, settings)


def test_a_spent_time_budget_leaves_the_comparison_and_the_simplification_to_the_report(
    tmp_path, monkeypatch
):
    """A time budget holds: once it is spent, the runner records the assessment but not the
    comparison of forms nor the simplification, and says so; the end screen names the
    command that does both, and the report does them."""
    from sga_agent.cli.progress import print_result
    from sga_agent.report.findings import DEFERRED

    ComparingTask.handed = []
    store, result = run_through_the_runner(tmp_path, monkeypatch, ComparingTask(),
                                           (5.0, 3.0, 7.0, 1.0, 1.5, 4.0), SlowLossInCode(),
                                           max_seconds=0.5)  # fmt: skip
    summary = store.summary()
    assert summary["stopped"] == "max_seconds=0.5 reached"  # after the first iteration
    found = summary["findings"]
    assert found["verdict"] == "the best law does not reproduce the motion"  # assessed
    assert found["identifiability"] is None and found["simplified"] is None
    assert found["deferred"] == DEFERRED and ComparingTask.handed == []
    screen = Console(file=io.StringIO(), width=80, record=True, color_system=None)
    print_result(screen, store, result, False, ComparingTask(), config())
    assert f"identifiability: {DEFERRED}" in screen.export_text()

    monkeypatch.setattr("sga_agent.report.build.load_or_none",
                        lambda name: as_task(ComparingTask()))  # fmt: skip
    report = CliRunner().invoke(main, ["report", str(store.path), "--json"])
    assert report.exit_code == 0, report.output
    again = json.loads(report.stdout)["findings"]
    assert again["identifiability"]["sentence"] and again["simplified"] and not again["deferred"]


class UnstableScreens(TwoFidelities):
    """The multi-fidelity evaluator double; a law whose screen loss is written as -1 blows up
    in its screen."""

    def submit(self, task, solution, settings, captured=None):
        future = super().submit(task, solution, settings, captured)
        if future.result().loss < 0:
            future._result = Evaluation.invalid("the stress is NaN at step 12", status="unstable")
        return future


def test_a_multi_fidelity_report_shows_its_screens_as_the_end_screen_counts_them(tmp_path):
    """The summary counts the screens beside the full fits in the end screen's words, the
    outcomes section charts and tables them, and the candidate table says per candidate how
    its screen ended and whether it was promoted to a full fit."""
    from sga_agent.cli.progress import print_result
    from tasks.constitutive.task import ElasticTask

    cfg = fidelity_config()
    store = RunStore.create(tmp_path, cfg, {"proposer": "scripted"})
    unstable = {7.0, 8.0, 10.0}  # their screens blow up
    losses = (9.0, 3.0, 7.0, 5.0, 8.0, 6.0) + (2.0, 4.0, 1.0, 10.0, 11.0, 9.0)  # 9 repeated
    answers = [fidelity_law(v, -1 if v in unstable else None) for v in losses]
    result = Search(cfg, FakeTask(), Scripted(answers), UnstableScreens(), store).run()
    screen = Console(file=io.StringIO(), width=120, record=True, color_system=None)
    print_result(screen, store, result, False, ElasticTask(), cfg)
    said = re.search(r"\d+ evaluations \(.*?\) after \d+ screens \(.*?\)", screen.export_text())
    # the repeat is not counted; promoted: the law of loss 3 in iteration 1, then those of 1
    # and 2 (the only ones whose screens beat the best earlier screen, 3's)
    assert said and said[0] == "4 evaluations (4 ok) after 11 screens (8 ok, 3 unstable)"

    report = CliRunner().invoke(main, ["report", str(store.path), "--no-motion"])
    assert report.exit_code == 0, report.output
    md = (store.path / "report" / "report.md").read_text()
    page = (store.path / "report" / "report.html").read_text()
    summary = md.split("## Bilevel")[0]
    assert f"- {said[0]} in " in summary
    assert (
        "- screens: candidates were screened by a short fit (0.2 of a full fit), whose loss "
        "compares only with other screens'; **3 of the 11 screens** were promoted"
    ) in summary
    assert f"<li>{said[0]} in " in page and "<b>3 of the 11 screens</b>" in page
    outcomes = md.split("## Outcomes per iteration")[1].split("## Candidates")[0]
    assert "screens (hatched, left) and full fits (plain, right)" in outcomes
    assert "| " + " | ".join(["iteration", *STATUSES, "screens", "promoted"]) + " |" in outcomes
    assert STATUSES[:4] == ("ok", "invalid", "error", "unstable")
    assert "| 1 | 4 | 0 | 0 | 2 | 0 | 0 | 0 | 6 | 1 |" in outcomes
    assert "| 2 | 5 | 0 | 0 | 1 | 0 | 0 | 0 | 6 | 2 |" in outcomes  # the repeat counts here
    seed_rows = [line for line in outcomes.splitlines() if line.startswith("| 0 |")]
    assert len(seed_rows) == 1  # the seed's full fit; no screen row for iteration 0
    table = md.split("## Candidates")[1].split("<details>")[0]
    assert "| loss | screen | fitted |" in table
    rows = {line.split(" | ")[0][2:]: line for line in table.splitlines() if line[2:4].isdigit()}
    assert "| ok |  | 3 | 0.003 ok, promoted |" in rows["01-exploit-01"]
    assert "| unstable (screen) | unstable: the stress is NaN at step N | - | unstable, not " \
        "promoted |" in rows["01-explore-00"]  # fmt: skip
    assert "| ok (screen) |  | 0.009 | 0.009 ok, not promoted |" in rows["01-exploit-00"]
    assert "| ok |  | 100 |  |" in rows["00-seed"]  # fitted in full, never screened
    assert "<td>3</td><td>0.003 ok, promoted</td>" in page

    figure = outcomes_figure(read_run(store.path))
    axes = figure.axes[0]
    legend = [text.get_text() for text in axes.get_legend().get_texts()]
    assert legend == ["ok", "unstable", "screens", "full fits"]
    hatched = [bar for bar in axes.patches if bar.get_hatch()]
    assert sum(bar.get_height() for bar in hatched) == 12  # every screen, the repeat too
    assert sum(bar.get_height() for bar in axes.patches if not bar.get_hatch()) == 4


@pytest.mark.parametrize("losses", [[0.37], [0.0], [0.5, 0.4], [2.0] * 5])
def test_a_fit_of_one_or_two_evaluations_is_drawn_around_its_values(losses):
    """A fit that stopped after one evaluation (or two, or whose loss never moved) is drawn as
    markers with their values written above them, on integer epochs, with y-limits around
    the values (not matplotlib's -0.05 to 0.05 around one point)."""
    candidate = Candidate("01-exploit-00", "ok", losses[-1],
                          curves={"loss": losses, "scale": [2.5e5] * len(losses)})  # fmt: skip
    figure = curves_figure([candidate], "loss")
    loss, scale = figure.axes[:2]
    for axes, values in ((loss, losses), (scale, [2.5e5] * len(losses))):
        low, high = axes.get_ylim()
        assert low < min(values) and max(values) < high
        assert high - low >= (0.1 * max(abs(v) for v in values) or 1.0)  # not 0.11 about 0
        left, right = axes.get_xlim()
        assert left < 0 and len(values) - 1 < right and right - left >= 1
        shown = [tick for tick in axes.get_xticks() if left <= tick <= right]
        assert shown and all(float(tick).is_integer() for tick in shown)  # epochs: 0, 1, ...
        labels = [text.get_text() for text in axes.texts]
        if len(values) <= 2:
            assert labels == [f"{value:.4g}" for value in values]
        else:  # all equal: the value once
            assert labels == [f"{values[0]:.4g}"]


def test_the_report_tells_each_stage_and_how_long_it_runs(tmp_path, monkeypatch):
    """In a pipe, stderr names each stage as it starts, then (here at once; in use after each
    5 s without a line, from the command's 5th second on) the running one with its time."""
    from sga_agent.report import heartbeat

    for name in ("GRACE_S", "EVERY_S"):
        monkeypatch.setattr(heartbeat, name, 0.0)
    cfg = config()
    store = RunStore.create(tmp_path, cfg, {"proposer": "scripted"})
    answers = [LAW.format(value=v) for v in (5.0, 3.0, 7.0, 1.0, 2.0, 4.0)]
    Search(cfg, FakeTask(), Scripted(answers), CurvesAndFailures(), store).run()

    result = CliRunner().invoke(main, ["report", str(store.path), "--no-motion"])
    assert result.exit_code == 0, result.output
    told = result.stderr.splitlines()
    assert told[:1] == [f"reading the run in {store.path}..."]
    assert "plotting the losses..." in told
    assert re.search(r"^still reading the run in .+ \[0:00:0\d\]$", result.stderr, re.M), told
    assert re.search(r"^still plotting the losses \[0:00:0\d\]$", result.stderr, re.M), told
    assert result.stdout.splitlines()[0] == str(store.path / "report" / "report.md")


def test_a_stage_in_short():
    from sga_agent.cli.report import short

    stage = "assessing the best solution: the true law's loss (cached after the first time)"
    assert short(stage) == "assessing the best solution"
    assert short("drawing the free run (training scene)") == "drawing the free run"
    assert short("plotting the losses") == "plotting the losses"
