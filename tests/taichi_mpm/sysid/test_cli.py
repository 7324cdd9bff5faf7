"""``scripts/make_observation.py`` and ``taichi-mpm sysid``: a synthetic fit end to end."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from matplotlib.image import imread

import taichi_mpm as tm
from taichi_mpm import runtime
from taichi_mpm.cli import main
from taichi_mpm.sysid import load_observation
from taichi_mpm.sysid.families import (
    DEFAULTS,
    FAMILIES,
    FamilyError,
    material_family,
    parse_assignment,
)

pytestmark = pytest.mark.slow  # each command simulates an observation first

REPO_ROOT = Path(__file__).resolve().parents[3]
SCRIPT = REPO_ROOT / "scripts" / "make_observation.py"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
HIDDEN_E = 5e4  # the neo-Hookean family's default


def make_observation(path: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(SCRIPT), str(path), *args],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )


@pytest.fixture(scope="module")
def observed(tmp_path_factory) -> Path:
    """A neo-Hookean cube (hidden E = 5e4, nu = 0.3) thrown at the floor: 60 steps, 6 frames."""
    path = tmp_path_factory.mktemp("observation") / "neohookean.npz"
    args = ["--material", "neohookean", "--scene", "thrown", "--steps", "60", "--frames", "6"]
    done = make_observation(path, *args)
    assert done.returncode == 0, done.stderr
    assert "hidden parameters: E=50000, nu=0.3" in done.stdout
    assert f"wrote {path}" in done.stdout
    return path


@pytest.mark.slow
def test_make_observation_writes_a_loadable_file(observed):
    observation = load_observation(observed)
    assert observation.positions.shape == (6, 125, 3)
    np.testing.assert_array_equal(observation.frame_steps, [10, 20, 30, 40, 50, 60])
    assert observation.scene.dt == 4e-4 and observation.scene.grid_resolution == 16


@pytest.mark.slow
def test_sysid_recovers_youngs_modulus(observed, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = [
        "sysid",
        str(observed),
        "--material",
        "neohookean",
        "--fit",
        "E",
        "--guess",
        "E=1e5",
        "--optimizer",
        "lbfgs",
        "--lr",
        "0.5",
        "--iterations",
        "15",
        "--precision",
        "float64",
        "--out-dir",
        "tmp/sysid",
    ]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert runtime.current().precision == "float64"
    out = tmp_path / "tmp" / "sysid"
    assert "best loss" in result.output  # the summary
    assert "fit.json" in result.output and "comparison.png" in result.output

    record = json.loads((out / "fit.json").read_text())
    assert abs(record["values"]["E"] / HIDDEN_E - 1.0) < 0.05, record["values"]
    assert record["parameters"]["nu"] == 0.3  # not fitted: stays at the family default
    assert record["fitted"] == ["E"]
    assert record["guess"]["E"] == 1e5
    assert 1 <= record["iterations"] <= 15
    assert len(record["loss_curve"]) == record["iterations"] == len(record["history"]["E"])
    assert record["loss_curve"][-1] < 1e-3 * record["loss_curve"][0]
    assert isinstance(record["warnings"], list)
    assert set(record["relative_std"]) == {"E"}

    png = out / "comparison.png"
    assert png.read_bytes()[:8] == PNG_SIGNATURE
    image = imread(png)
    assert image.ndim == 3 and image.shape[0] > 100 and image.shape[1] > 400
    assert np.ptp(image[..., :3]) > 0.5  # not a blank picture


def test_sysid_missing_file_is_a_usage_error(tmp_path):
    """Exit 2, as `sga-agent evaluate` for a missing file."""
    result = CliRunner().invoke(
        main, ["sysid", str(tmp_path / "absent.npz"), "--material", "neohookean"]
    )
    assert result.exit_code == 2, result.output
    assert "'OBSERVED'" in result.output and "absent.npz' does not exist" in result.output
    assert "Traceback" not in result.output
    assert not (tmp_path / "sysid_out").exists()


def test_sysid_file_that_is_not_an_observation(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_text("not numbers")
    result = CliRunner().invoke(main, ["sysid", str(bad), "--material", "sand"])
    assert result.exit_code == 1, result.output
    assert "is not a NumPy .npz archive" in result.output


@pytest.mark.slow
def test_make_observation_refines_the_paper_scene(tmp_path):
    path = tmp_path / "fine.npz"
    args = ["--material", "neohookean", "--scene", "paper", "--particles-per-side", "12",
            "--steps", "20", "--frames", "2"]  # fmt: skip
    done = make_observation(path, *args)
    assert done.returncode == 0, done.stderr
    assert "1728 particles, grid 24^3" in done.stdout
    scene = load_observation(path).scene
    coarse = tm.paper_scene(steps=20)
    assert scene.num_particles == 12**3 and scene.grid_resolution == 24
    assert scene.dt == coarse.dt and scene.walls == coarse.walls
    assert np.ptp(scene.positions, axis=0).max() == pytest.approx(0.5 * 11 / 12)
    assert scene.particle_volume * 12**3 == pytest.approx(coarse.particle_volume * 10**3)


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["--material", "granite"], "neohookean"),  # the valid choices are named
        (["--material", "neohookean", "--guess", "E"], "NAME=VALUE"),
        (["--material", "neohookean", "--guess", "E=soft"], "not a number"),
        (["--material", "neohookean", "--guess", "yield_stress=1e3"], "'E', 'nu'"),
        (["--material", "neohookean", "--guess", "nu=0.7"], "nu=0.7"),
        (["--material", "vonmises", "--fit", "friction_angle"], "yield_stress"),
        (["--material", "sand", "--fit", "cohesion"], "--guess cohesion="),
        (["--material", "sand", "--optimizer", "sgd"], "lbfgs"),
        (["--material", "sand", "--restarts", "0"], "--restarts"),
    ],
)
def test_sysid_rejects_bad_arguments(observed, tmp_path, monkeypatch, args, fragment):
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(main, ["sysid", str(observed), *args])
    assert result.exit_code == 2, result.output
    assert "Invalid value" in result.output
    assert fragment in result.output
    assert "Traceback" not in result.output
    assert not list(tmp_path.iterdir())  # nothing written


def test_sysid_help_lists_families():
    result = CliRunner().invoke(main, ["sysid", "--help"])
    assert result.exit_code == 0
    for name in FAMILIES:
        assert name in result.output


@pytest.mark.slow
def test_make_observation_subset_and_noise(tmp_path):
    path = tmp_path / "sand.npz"
    args = ["--material", "sand", "--param", "friction_angle=35", "--steps", "30", "--frames", "3"]
    done = make_observation(path, *args, "--subset", "0.5", "--noise", "0.01", "--seed", "3")
    assert done.returncode == 0, done.stderr
    assert "friction_angle=35" in done.stdout
    observation = load_observation(path)
    indices = observation.particle_indices
    assert len(indices) == 62 and np.all(np.diff(indices) > 0)  # 50% of 125, sorted
    exact = tm.Simulator(observation.scene, material_family("sand", friction_angle=35)).forward(
        observation.frame_steps
    )[:, indices]
    noise = (observation.positions - exact) / observation.body_size
    assert 0.008 < noise.std() < 0.012


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["--material", "granite"], "neohookean"),
        (["--material", "sand", "--param", "yield_stress=1e3"], "friction_angle"),
        (["--material", "sand", "--param", "E"], "NAME=VALUE"),
        (["--material", "sand", "--subset", "0"], "--subset"),
        (["--material", "sand", "--particles-per-side", "20"], "add --scene paper"),
    ],
)
def test_make_observation_rejects_bad_arguments(tmp_path, args, fragment):
    done = make_observation(tmp_path / "x.npz", *args)
    assert done.returncode == 2
    assert fragment in done.stderr
    assert "Traceback" not in done.stderr
    assert not list(tmp_path.iterdir())


def test_make_observation_is_a_click_command():
    done = subprocess.run(
        [sys.executable, str(SCRIPT), "--help"], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("Usage: make_observation.py [OPTIONS] OUT")
    assert "vonmises" in done.stdout and "--noise FLOAT RANGE" in done.stdout


def test_every_family_builds_with_its_default_parameters():
    for name in FAMILIES:
        material = material_family(name)
        assert material.parameters() == pytest.approx(DEFAULTS[name]), name
    material = material_family("imaginary", weight_fluid=0.4, E=3e4)
    assert material.parameters()["weight_fluid"] == 0.4
    assert material.elastic == tm.StVKHencky(E=3e4, nu=0.3)
    assert isinstance(material_family("neohookean").elastic, tm.NeoHookean)
    assert isinstance(material_family("corotated").elastic, tm.FixedCorotated)
    assert isinstance(material_family("linear").elastic, tm.LinearElastic)
    assert isinstance(material_family("fluid").plastic, tm.WeaklyCompressibleFluid)


def test_family_errors_name_the_valid_choices():
    with pytest.raises(FamilyError, match="use one of.*'neohookean'.*'imaginary'"):
        material_family("granite")
    with pytest.raises(FamilyError, match=r"\['yield_stress'\].*\['E', 'nu'\]"):
        material_family("neohookean", yield_stress=1e3)
    with pytest.raises(tm.MaterialError, match="nu=0.7"):
        material_family("neohookean", nu=0.7)
    assert parse_assignment(" E = 5e4 ") == ("E", 5e4)
    for text in ("E", "=1", "E=x", "E=nan"):
        with pytest.raises(ValueError):
            parse_assignment(text)


@pytest.mark.slow
def test_sysid_in_a_pipe_tells_each_iteration_and_phase(observed, tmp_path, prompt_lines):
    """No bar is drawn in a pipe: plain lines on stderr tell the iterations with their loss and
    the phases (here at once; in use from 5 s on, one each 5 s); stdout stays as it was."""
    args = ["sysid", str(observed), "--material", "neohookean", "--fit", "E", "--guess", "E=1e5",
            "--optimizer", "lbfgs", "--lr", "0.5", "--iterations", "4", "--precision", "float64",
            "--out-dir", str(tmp_path / "out")]  # fmt: skip
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    told = result.stderr.splitlines()
    assert told[0] == "starting Taichi [0:00:00]", result.stderr
    assert any(line.startswith("fitting E with lbfgs, at most 4 iterations") for line in told)
    assert any(line.startswith("fitting: iteration 1/4, loss ") for line in told), told
    assert any(line.startswith("uncertainties: 2 simulations around the best fit") for line in told)
    assert any(line.startswith("writing fit.json and comparison.png to ") for line in told)
    assert not any("Fitting" in line or "best loss" in line for line in told)
    assert "fitting: iteration" not in result.stdout
    assert "best loss" in result.stdout and "done" in result.stdout
