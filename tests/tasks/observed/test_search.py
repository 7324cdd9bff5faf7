"""The ``observed`` task end to end at CI size: a synthetic observation (a subset of the
particles, noisy positions) of a von Mises body is searched by the built-in genetic
programming through ``sga-agent search``, sandbox included, and a law at least 5x better than
the seed comes out; the report's assessment reads the hidden truth."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.plugins import REPO

YIELD_STRESS, E, NU = 1e3, 5e4, 0.3


def make_observation(path: Path) -> None:
    """A small cube thrown onto the floor (64 particles, 160 steps, impact after about 15),
    observed at 10 frames, 40% of its particles, noise 1% of its size; the truth beside it."""
    import taichi_mpm as tm
    from taichi_mpm.sysid import observation_from_times, save_observation

    positions, volume = tm.cube((0.45, 0.245, 0.5), 0.2, 4)
    velocities = tm.rigid_velocity(positions, (0.5, -3.0, 0.2), (1.0, -1.0, 2.0))
    scene = tm.Scene(positions, velocities, volume, grid_resolution=16, dt=4e-4, steps=160)
    material = tm.Material(tm.StVKHencky(E, NU), tm.VonMises(YIELD_STRESS))
    steps = np.arange(16, 161, 16)
    rng = np.random.default_rng(1)
    moved = tm.Simulator(scene, material).forward(steps)
    observed = np.sort(rng.choice(64, 26, replace=False))
    noisy = moved[:, observed] + 0.01 * 0.15 * rng.standard_normal((len(steps), 26, 3))
    save_observation(path, observation_from_times(scene, noisy, steps * scene.dt, observed))
    path.with_suffix(".truth.json").write_text(json.dumps(
        {"family": "vonmises", "parameters": {"E": E, "nu": NU, "yield_stress": YIELD_STRESS}}
    ))  # fmt: skip


@pytest.mark.heavy  # a minute of search quality: benchmarks/discovery.py measures it in full
def test_the_gp_finds_a_law_5x_better_than_the_seed(registered, tmp_path: Path) -> None:
    observation = tmp_path / "observed.npz"
    subprocess.run([sys.executable, "-c", (
        "import sys; from pathlib import Path; import taichi_mpm as tm; "
        "from tests.tasks.observed.test_search import make_observation; "
        "tm.init(precision='float64'); make_observation(Path(sys.argv[1]))"
    ), str(observation)], check=True, cwd=REPO, env=registered)  # fmt: skip
    command = [
        sys.executable, "-c", "import sys; from sga_agent.cli import main; sys.exit(main())",
        "search", "--task", "observed",
        "--option", f"observation={observation}", "--option", "searched=plastic",
        "--option", f"E={E}", "--option", f"nu={NU}", "--option", "segment=40",
        "--model", "builtin", "--iterations", "4", "--workers", "2",
        "--out-dir", str(tmp_path / "runs"), "--json",
    ]  # fmt: skip
    done = subprocess.run(command, cwd=tmp_path, env=registered, capture_output=True, text=True,
                          timeout=600)  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    summary = json.loads(done.stdout)
    run = Path(summary["run"])
    seed = json.loads((run / "candidates" / "00-seed" / "evaluation.json").read_text())
    best = min(
        json.loads(path.read_text())["loss"] if json.loads(path.read_text())["status"] == "ok"
        else float("inf")
        for path in run.glob("candidates/*/evaluation.json")
    )  # fmt: skip
    assert seed["loss"] / best >= 5, (seed["loss"], best)
    findings = json.loads((run / "summary.json").read_text())["findings"]
    assert "yield_stress = 1000" in findings["truth"]
    assert findings["truth_loss"] is not None and findings["truth_loss"] <= best
