"""The ``taichi-mpm`` command line: demo run, PNG output, user errors, help."""

import os
import struct
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from matplotlib.image import imread

from taichi_mpm import runtime
from taichi_mpm.cli import main
from taichi_mpm.cli.demo import MATERIALS, frame_steps
from taichi_mpm.render import figure_size

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
REPO_ROOT = Path(__file__).resolve().parents[2]


def png_size(path: Path) -> tuple[int, int]:
    """(width, height) from the IHDR chunk, which must directly follow the signature."""
    data = path.read_bytes()
    assert data[:8] == PNG_SIGNATURE
    length, kind = struct.unpack(">I4s", data[8:16])
    assert (length, kind) == (13, b"IHDR")
    return struct.unpack(">II", data[16:24])


@pytest.mark.slow
def test_demo_writes_png(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    # float64 keeps the session's runtime (tests/conftest.py) as the other tests expect.
    args = ["demo", "--steps", "40", "--frames", "2", "--out", "tmp/x.png"]
    result = CliRunner().invoke(main, [*args, "--precision", "float64"])
    assert result.exit_code == 0, result.output
    out = tmp_path / "tmp" / "x.png"
    assert out.is_file()
    assert "wrote" in result.output and "x.png" in result.output
    assert png_size(out) == figure_size(2) == (990, 450)  # 2 panels of 3 in + 0.6 in, 150 dpi
    image = imread(out)
    assert image.shape[:2] == (450, 990)
    assert np.ptp(image[..., :3]) > 0.5  # not a blank picture
    assert runtime.current().precision == "float64"


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["--material", "granite"], "plasticine"),
        (["--frames", "0"], "--frames"),
        (["--steps", "-5"], "--steps"),
        (["--arch", "tpu"], "cuda"),
        (["--out", "picture.jpg"], ".png"),
    ],
)
def test_demo_rejects_bad_values(tmp_path, monkeypatch, args, fragment):
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(main, ["demo", *args])
    assert result.exit_code == 2, result.output
    assert "Invalid value" in result.output
    assert fragment in result.output
    assert "Traceback" not in result.output
    assert not list(tmp_path.iterdir())  # nothing written, nothing simulated


def test_demo_rejects_output_under_a_file(tmp_path):
    (tmp_path / "file").write_text("")
    result = CliRunner().invoke(main, ["demo", "--out", str(tmp_path / "file" / "x.png")])
    assert result.exit_code == 2
    assert "not a directory" in result.output


def test_help_lists_materials():
    result = CliRunner().invoke(main, ["demo", "--help"])
    assert result.exit_code == 0
    for name in MATERIALS:
        assert name in result.output
    top = CliRunner().invoke(main, ["--help"])
    assert top.exit_code == 0 and "demo" in top.output


def test_frame_steps_are_evenly_spaced():
    assert frame_steps(1000, 4).tolist() == [0, 333, 667, 1000]
    assert frame_steps(40, 2).tolist() == [0, 40]
    assert frame_steps(10, 1).tolist() == [10]


def test_python_dash_m_runs_the_cli():
    result = subprocess.run(
        [sys.executable, "-m", "taichi_mpm", "--help"],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    assert "demo" in result.stdout


def test_help_comes_without_taichis_banner_and_version_is_known():
    env = {k: v for k, v in os.environ.items() if k != "ENABLE_TAICHI_HEADER_PRINT"}
    command = [sys.executable, "-m", "taichi_mpm"]
    helped = subprocess.run([*command, "--help"], capture_output=True, text=True, env=env)
    assert helped.returncode == 0, helped.stderr
    assert helped.stdout.startswith("Usage: taichi-mpm") and "[Taichi]" not in helped.stderr
    version = CliRunner().invoke(main, ["--version"])
    assert version.exit_code == 0
    assert version.output == f"taichi-mpm, version {metadata.version('sga-agent')}\n"


@pytest.mark.heavy
def test_warmup_compiles_and_reports():
    result = CliRunner().invoke(main, ["warmup", "--precision", "float64"])
    assert result.exit_code == 0, result.output
    assert "compiled cpu float64 kernels" in result.output
    assert runtime.current().precision == "float64"


def test_warmup_in_a_pipe_names_each_pass_i_of_n(monkeypatch, prompt_lines):
    """What it compiles, law and pass, i of N: in a pipe (no live display) as plain lines."""
    from taichi_mpm.cli import warmup

    def passes():
        yield from ("LinearElastic + NoPlasticity, serial loops, forward", "a second pass")

    monkeypatch.setattr(warmup, "warm_up_passes", passes)
    monkeypatch.setattr(warmup, "start_taichi", lambda console, arch, precision: "cpu")
    result = CliRunner().invoke(main, ["warmup", "--precision", "float32"])
    assert result.exit_code == 0, result.output
    title = "compiling cpu float32 kernels"
    assert sorted(result.output.splitlines()) == [  # a thread prints them: in its own time
        "compiled cpu float32 kernels in 0.0 s",
        f"{title}: 1/{warmup.PASSES} LinearElastic + NoPlasticity, serial loops, forward [0:00:00]",
        f"{title}: 2/{warmup.PASSES} a second pass [0:00:00]",
    ]


def test_warmup_names_the_passes_warm_up_runs():
    from taichi_mpm.cli import warmup
    from taichi_mpm.warmup import WARM_UP_MATERIALS, warm_up_passes

    names = [f"{type(m.elastic).__name__} + {type(m.plastic).__name__}" for m in WARM_UP_MATERIALS]
    passes = warm_up_passes()
    first = [next(passes) for _ in range(2)]  # runs the first law forward: seconds when cached
    assert first == [f"{names[0]}, serial loops, forward", f"{names[0]}, serial loops, backward"]
    assert warmup.PASSES == 16 == 2 * 2 * len(names)


@pytest.mark.slow
def test_demo_in_a_pipe_says_what_it_does(tmp_path, prompt_lines):
    """No live display in a pipe: plain lines name the simulation and the picture."""
    args = ["demo", "--steps", "20", "--frames", "2", "--out", str(tmp_path / "x.png")]
    result = CliRunner().invoke(main, [*args, "--precision", "float64"])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    simulating = [line for line in lines if line.startswith("Simulating plasticine: 1000 ")]
    assert simulating and simulating[0].endswith("compiles the kernels (about a minute) [0:00:00]")
    assert any(line.startswith("Rendering 2 panels [0:00:") for line in lines), result.output
    assert "[bold]" not in result.output
