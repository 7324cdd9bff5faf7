"""The ``observed`` task's held-out scene (``--option validation=PATH.npz``), its verdict and
motion pictures, and what a run records at its start: a report of a run whose observation was
rewritten since says so and names the truth the run was measured against."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from sga_agent.cli import main
from sga_agent.config import SearchConfig
from sga_agent.run_store import SEED, RunStore
from sga_agent.task import Evaluation, ReportView
from tasks.observed import ObservedTask
from tasks.observed.options import ObservedOptions
from tests.tasks.observed.conftest import observation_arrays
from tests.tasks.observed.test_options import search, write

ROOT = Path(__file__).resolve().parents[3]
E, NU = 5e4, 0.3
TRUTH = {"family": "neohookean", "parameters": {"E": E, "nu": NU}}


def simulate(path: Path, centre, velocity, spin, steps: int, material=TRUTH) -> Path:
    """A 3^3-particle cube thrown at the floor of a 16^3 grid, every particle observed at 6
    frames; the hidden truth beside it, as scripts/make_observation.py writes it."""
    import taichi_mpm as tm
    from taichi_mpm.sysid import observation_from_times, save_observation
    from taichi_mpm.sysid.families import material_family

    positions, volume = tm.cube(centre, 0.15, 3)
    velocities = tm.rigid_velocity(positions, velocity, spin)
    scene = tm.Scene(positions, velocities, volume, grid_resolution=16, dt=4e-4, steps=steps)
    frames = np.linspace(steps / 6, steps, 6).round().astype(int)
    moved = tm.Simulator(scene, material_family(material["family"], **material["parameters"]))
    observed = moved.forward(frames)
    save_observation(path, observation_from_times(scene, observed, frames * scene.dt))
    path.with_suffix(".truth.json").write_text(json.dumps(material))
    return path


@pytest.fixture
def observed_pair(tmp_path: Path) -> tuple[Path, Path]:
    """An observation and a validation file of the same neo-Hookean body in two scenes."""
    training = simulate(tmp_path / "training.npz", (0.45, 0.27, 0.5), (0.5, -2.5, 0.2),
                        (1.0, -1.0, 2.0), 90)  # fmt: skip
    held_out = simulate(tmp_path / "held_out.npz", (0.5, 0.35, 0.45), (-0.4, -3.0, 0.3),
                        (-2.0, 1.0, 1.0), 120)  # fmt: skip
    return training, held_out


def captured(name: str) -> dict:
    from tasks.constitutive.law_capture import capture_law

    return {"captured": {"law": capture_law(name)}}


def test_the_best_law_is_judged_on_the_validation_file(observed_pair, tmp_path: Path) -> None:
    """The true law (examples/laws/neo_hookean.py at the hidden values) follows the validation
    file, which it was not fitted to; the linear seed does not; the verdicts say so; the
    report draws the free run."""
    from tasks.constitutive import report
    from tasks.constitutive.prompt_text import ELASTIC_SEED

    observation, validation = observed_pair
    options = ObservedOptions(str(observation), "elastic", validation=str(validation))
    task = ObservedTask(options)
    truth_code = (ROOT / "examples/laws/neo_hookean.py").read_text()
    values = {"log_youngs_modulus": math.log(E), "poissons_ratio": NU}
    good = task.assess(captured(truth_code), values, options, simulate=True)
    bad = task.assess(captured(ELASTIC_SEED), {}, options, simulate=True)
    assert good.held_out.scene == "held-out scene" and good.free_run.scene == "training scene"
    assert good.held_out.steps == 120 and good.free_run.steps == 90
    assert good.held_out.final_error < 1e-6 and good.free_run.final_error < 1e-6
    assert bad.held_out.final_error > 0.05
    assert good.verdict.startswith("the best law reproduces the motion: ")
    assert "on the held-out scene" in good.verdict
    assert bad.verdict.startswith("the best law does not reproduce the motion: ")
    assert good.to_dict()["held_out"]["final_error"] == good.held_out.final_error
    assert good.truth.startswith("neo-Hookean") and good.truth_loss < 1e-12
    lines = report.free_run_line(bad, simulate=True)
    assert [line.split("**")[1] for line in lines] == ["training scene", "held-out scene"]

    view = ReportView("observed", _Best(), [], bad, tmp_path, True)
    section = task.report_sections(view)[0]
    assert section.title.startswith("Free run")
    drawn = [block.file for block in section.blocks if hasattr(block, "file")]
    assert drawn == ["motion.png", "motion.gif", "motion-held-out.png", "motion-held-out.gif"]
    for name in drawn:
        assert (tmp_path / name).read_bytes()[:3] in (b"\x89PN", b"GIF")


class _Best:
    id = "03-explore-01"


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda folder, obs: folder / "nowhere.npz", "no observation file at"),
        (lambda folder, obs: obs, "names the observation itself"),
        (lambda folder, obs: write(folder / "dense.npz", density=2e3), "density 2000"),
        (lambda folder, obs: _with_truth(write(folder / "other.npz"), "vonmises"),
         "is not the observation's"),
    ],
)
def test_a_bad_validation_file_is_a_usage_error(registered, tmp_path, make, message) -> None:
    observation = _with_truth(write(tmp_path / "observed.npz"), "neohookean")
    validation = make(tmp_path, observation)
    result = search(registered, tmp_path, observation, "--option", "searched=elastic",
                    "--option", f"validation={validation}")  # fmt: skip
    assert result.exit_code == 2, result.output
    assert "option 'validation'" in result.output and message in result.output


def _with_truth(path: Path, family: str) -> Path:
    path.with_suffix(".truth.json").write_text(
        json.dumps({"family": family, "parameters": {"E": E, "nu": NU}})
    )
    return path


def test_a_good_validation_file_is_accepted_and_made_absolute(tmp_path, monkeypatch) -> None:
    write(tmp_path / "observed.npz")
    write(tmp_path / "other.npz")
    monkeypatch.chdir(tmp_path)
    options = ObservedOptions("observed.npz", "elastic", validation="other.npz")
    assert options.validation == str(tmp_path / "other.npz")


def test_a_report_says_the_observation_changed_and_names_the_recorded_truth(
    registered, tmp_path: Path
) -> None:
    """A run records the observation's sha256 and truth at its start; the observation is then
    made again with another material into the same file; the report says so and names the
    truth of the run, not the new one (and simulates nothing against the new file)."""
    from sga_agent.runner import record_findings
    from tasks.constitutive.prompt_text import ELASTIC_SEED

    observation = _with_truth(write(tmp_path / "observed.npz"), "neohookean")
    options = ObservedOptions(str(observation), "elastic")
    task = ObservedTask(options)
    config = SearchConfig(task="observed", proposer="builtin", task_options=options)
    store = RunStore.create(tmp_path / "runs", config, {})
    store.record_provenance(task.provenance(options))
    store.save_evaluation(SEED, ELASTIC_SEED, Evaluation(True, 1e-3, "fit", artifacts=captured(
        ELASTIC_SEED)))  # fmt: skip
    recorded = json.loads((store.path / "provenance.json").read_text())
    assert recorded["truth"] == TRUTH and len(recorded["observation_sha256"]) == 64

    arrays = observation_arrays()
    write(observation, initial_velocities=np.ones_like(arrays["initial_velocities"]))
    observation.with_suffix(".truth.json").write_text(
        json.dumps({"family": "neohookean", "parameters": {"E": 9e4, "nu": 0.2}})
    )
    result = CliRunner().invoke(main, ["report", str(store.path), "--json"])
    assert result.exit_code == 0, result.output
    found = json.loads(result.stdout)["findings"]
    assert found["truth"].startswith("neo-Hookean") and "E = 50000" in found["truth"]
    assert "E = 90000" not in found["truth"]
    assert found["free_run"] is None and found["held_out"] is None
    assert found["verdict"].startswith("not judged: the observation")
    changed = " ".join(found["changed_since_start"])
    assert "observation_sha256" in changed and "truth" in changed
    page = (store.path / "report" / "report.md").read_text()
    assert "**changed since the run started**" in page and "E = 50000" in page

    record_findings(store, task, options)  # the runner's end-of-search record reads the same
    assert store.summary()["findings"]["truth"] == found["truth"]
