"""Whether an observation determines the law: the probe scenes, the spread of motions on them,
and the comparison of real laws simulated there (physics: laws that are one law written twice
agree everywhere; a linear law and neo-Hookean part under a strong impact)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import taichi_mpm as tm
from tasks.constitutive.forms import cube_probes, probe_duration
from tasks.constitutive.options import ConstitutiveOptions
from tasks.constitutive.probes import DURATION, IMPACT_SPEED, STRETCH_RATE, probe_scenes, spread
from tasks.constitutive.specs import SPECS

ROOT = Path(__file__).resolve().parents[3]


def test_the_cube_probes_load_the_body_four_ways_on_the_paper_scene_s_set_up():
    base = tm.paper_scene(steps=1)
    probes = {probe.probe.name: probe for probe in cube_probes(base)}
    assert list(probes) == ["a stronger impact", "a stretch", "a shear",
                            "a collapse under its own weight"]  # fmt: skip
    for probe in probes.values():
        scene = probe.scene
        assert scene.num_particles == 216 and scene.steps == 300
        assert (scene.dt, scene.grid_resolution, scene.walls) == (base.dt, 20, base.walls)
        assert probe.probe.text.startswith("a cube of side 0.3 m (216 particles)")
        assert "for 0.15 s (300 steps of 0.0005 s)" in probe.probe.text
    impact = probes["a stronger impact"].scene
    assert np.allclose(impact.velocities, [0.0, -IMPACT_SPEED, 0.0])
    floor = base.walls.thickness * base.dx
    assert impact.positions[:, 1].min() == pytest.approx(floor + base.dx)  # a cell above it
    stretch = probes["a stretch"].scene
    assert np.allclose(stretch.positions.mean(axis=0), 0.5)  # in mid-air
    gradient = np.linalg.lstsq(np.c_[stretch.positions, np.ones(216)], stretch.velocities,
                               rcond=None)[0][:3]  # fmt: skip
    assert np.allclose(np.diag(gradient), [STRETCH_RATE, -STRETCH_RATE / 2, -STRETCH_RATE / 2])
    assert np.allclose(probes["a collapse under its own weight"].scene.velocities, 0.0)


def test_a_run_shortened_by_its_steps_option_shortens_the_probes_in_proportion():
    spec = SPECS["elastic"]
    assert probe_duration(spec, ConstitutiveOptions()) == DURATION
    assert probe_duration(spec, ConstitutiveOptions(steps=spec.steps // 5)) == pytest.approx(
        DURATION / 5)
    assert probe_duration(spec, ConstitutiveOptions(steps=2 * spec.steps)) == DURATION
    short = cube_probes(tm.paper_scene(steps=1), DURATION / 5)
    assert all(p.scene.steps == 60 and "for 0.03 s (60 steps" in p.probe.text for p in short)


def test_a_body_too_tall_to_rest_on_the_floor_keeps_only_the_probes_in_mid_air():
    base = tm.paper_scene(steps=1)
    body, volume = tm.cube((0.5, 0.5, 0.5), 0.8, 9)
    names = [probe.probe.name for probe in probe_scenes(base, body, volume, "a big cube")]
    assert names == ["a stretch", "a shear"]


def test_the_spread_is_the_largest_rms_distance_between_two_motions_in_body_sizes():
    still = np.zeros((5, 4, 3))
    moved = still.copy()
    moved[3, :, 0] = 0.1  # every particle 0.1 m off at one step
    assert spread([still, still], 0.5) == 0.0
    assert spread([still, moved, still], 0.5) == pytest.approx(0.2)
    assert spread([still, None], 0.5) == math.inf  # one of them blew up
    assert math.isnan(spread([None, None], 0.5))  # the probe tells nothing


@dataclass
class Recorded:
    """A scored candidate as a report reads it back (``CandidateRecord``)."""

    id: str
    loss: float
    captured: dict[str, Any]
    parameters: dict[str, float] = field(default_factory=dict)
    status: str = "ok"
    code: str = ""
    extras: dict[str, Any] = field(default_factory=dict)

    def artifacts(self) -> dict[str, Any]:
        return {"captured": self.captured}


NEO_HOOKEAN = (ROOT / "examples" / "laws" / "neo_hookean.py").read_text()
#: The same law with its terms written otherwise: one law, two codes.
REWRITTEN = NEO_HOOKEAN.replace(
    "return mu * (F @ F.transpose(-2, -1) - eye) + lam * torch.log(J) * eye",
    "return mu * (F @ F.transpose(-2, -1)) - mu * eye + lam * eye * torch.log(J)")


@pytest.mark.slow
def test_one_law_written_twice_agrees_and_a_linear_law_parts_from_it(tmp_path):
    """Real laws on the real probes (elastic task): neo-Hookean and its rewriting agree to
    float precision on every probe; the linear seed at the same stiffness, with an equal loss,
    parts from them under the strong impact by more than the threshold, and that probe is
    written as a scene file."""
    from sga_agent.registry import load_task
    from tasks.constitutive.options import ConstitutiveOptions

    assert REWRITTEN != NEO_HOOKEAN
    task = load_task("elastic")
    options = ConstitutiveOptions()
    law, twice = (task.capture(code) for code in (NEO_HOOKEAN, REWRITTEN))
    seed = task.capture(task.seed_solution())
    same = task.compare_forms([Recorded("a", 1e-6, law), Recorded("b", 1.5e-6, twice),
                               Recorded("c", 9e-6, seed)], options, tmp_path)  # fmt: skip
    assert same.forms == ["a", "b"] and same.determined and same.largest_spread < 1e-4
    parted = task.compare_forms([Recorded("a", 1e-6, law), Recorded("c", 1.2e-6, seed)],
                                options, tmp_path)  # fmt: skip
    assert not parted.determined and parted.largest_spread > 0.05
    assert parted.probe is not None and parted.probe.name == max(parted.spreads,
                                                                 key=parted.spreads.get)
    scene = tm.load_scene(parted.probe.file)
    assert Path(parted.probe.file).parent == tmp_path / "probes" and scene.num_particles == 216


def test_a_law_s_size_counts_its_operations_and_not_how_it_lays_data_out():
    """An added term ``+ mu * F`` is two operations (a product and a sum), however many views
    and broadcasts the capture records for it."""
    from sga_agent.registry import load_task

    task = load_task("elastic")
    term = "+ lam * torch.log(J) * eye"
    bigger = NEO_HOOKEAN.replace(term, term + " + mu * F")
    assert bigger != NEO_HOOKEAN
    size, larger = (task.solution_size(Recorded("a", 1.0, task.capture(code)))
                    for code in (NEO_HOOKEAN, bigger))  # fmt: skip
    assert larger == size + 2
    assert task.solution_size(Recorded("b", 1.0, {})) is None  # nothing captured: no size
