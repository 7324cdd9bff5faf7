"""Whether a constitutive run's observation determines its law: the distinct forms that fit
within the noise, simulated on probe scenes (:mod:`tasks.constitutive.probes`).

Trusted: each form is rebuilt from the graph its capture recorded (:func:`fitted_law`), with
its fitted values; no candidate code runs here.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import torch

import taichi_mpm as tm
from bridges.rollout import Rollout, UnstableSimulation
from bridges.step import torch_dtype
from sga_agent.task import CandidateRecord, FormComparison, compared, within_noise
from taichi_mpm.frames import evenly_spaced
from tasks.constitutive.evaluation import ensure_runtime, task_rollout
from tasks.constitutive.free_sim import fitted_law
from tasks.constitutive.law_graph import captured_graph
from tasks.constitutive.options import ConstitutiveOptions
from tasks.constitutive.probes import (
    DURATION,
    ProbeScene,
    probe_scenes,
    probe_spreads,
    written,
)
from tasks.constitutive.specs import ConstitutiveSpec
from tasks.constitutive.verdict import THRESHOLDS

#: Forms whose motions part by more than this on a probe (RMS over particles at some step, in
#: body sizes) disagree: the verdict's limit for a law that reproduces a motion, so that a
#: probe where they part by more would tell them apart by the verdict's own standard.
THRESHOLD = THRESHOLDS.reproduces
#: The constitutive tasks' probe body: a cube of side 0.3 m, particles 0.05 m apart (216), as
#: the paper's cube samples its body.
CUBE_SIDE, CUBE_PER_SIDE = 0.3, 6
#: The most positions (steps x particles) a probe's motion keeps of each law: every step of
#: the probe cube, about 70 evenly spaced steps of an observed body of 2.7e4 particles.
MOTION_POSITIONS = 2_000_000


def cube_probes(base: tm.Scene, duration: float = DURATION) -> list[ProbeScene]:
    """The probes of the constitutive tasks: :data:`CUBE_SIDE` cube on ``base``'s set-up,
    ``duration`` seconds long."""
    body, volume = tm.cube((0.5, 0.5, 0.5), CUBE_SIDE, CUBE_PER_SIDE)
    text = f"a cube of side {CUBE_SIDE:g} m ({len(body)} particles)"
    return probe_scenes(base, body, volume, text, duration)


def probe_duration(spec: ConstitutiveSpec, options: ConstitutiveOptions) -> float:
    """How long the probes of a run with ``options`` last: :data:`DURATION`, shortened in
    proportion where ``--option steps`` shortens the training scene (as the held-out scene
    is, :func:`~tasks.constitutive.held_out.held_out_steps`)."""
    if options.steps is None:
        return DURATION
    return DURATION * min(1.0, options.steps / spec.steps)


def compare_forms(
    candidates: Sequence[CandidateRecord],
    probes: Sequence[ProbeScene],
    rollout: Callable[[torch.nn.Module, tm.Scene], Rollout],
    floor: float | None,
    folder: Path | None,
) -> FormComparison | None:
    """The comparison of the distinct ``candidates`` (best first) whose loss is within the
    noise (:func:`~sga_agent.task.within_noise` of ``floor``): each rebuilt and simulated on
    ``probes`` in the scene ``rollout(law, scene)`` sets up. None with fewer than two scored
    forms."""
    graphs = {c.id: captured_graph(c.artifacts()) for c in candidates}  # read once each
    scored = [c for c in candidates if math.isfinite(c.loss) and graphs[c.id] is not None]
    if len(scored) < 2:
        return None
    losses = [c.loss for c in scored]
    band = within_noise(losses, floor)
    fitting = [c for c in scored if c.loss <= band]
    spreads: dict[str, float] = {}
    if len(fitting) > 1:
        dtype = torch_dtype()
        laws = [fitted_law(graphs[c.id], c.parameters, dtype) for c in fitting]
        spreads = probe_spreads(laws, probes, lambda law, scene: _motion(rollout(law, scene)))
    words = {probe.probe.name: probe for probe in probes}
    found = compared([c.id for c in scored], losses, band, spreads,
                     {name: probe.probe for name, probe in words.items()}, THRESHOLD)  # fmt: skip
    if found.probe is not None:
        found.probe = written(words[found.probe.name], folder)
    return found


def compare_task_forms(
    spec: ConstitutiveSpec,
    candidates: Sequence[CandidateRecord],
    options: ConstitutiveOptions,
    folder: Path | None,
) -> FormComparison | None:
    """:func:`compare_forms` for a constitutive task: the cube probes on the paper scene's
    set-up (:func:`probe_duration` long), the floor the true law's own loss (an exact
    observation's noise is float precision, which the true law's loss measures)."""
    from tasks.constitutive.assessment import truth_loss

    ensure_runtime(options.precision or "float32")
    probes = cube_probes(tm.paper_scene(steps=1), probe_duration(spec, options))
    return compare_forms(candidates, probes,
                         lambda law, scene: task_rollout(spec, law, scene),
                         truth_loss(spec, options), folder)  # fmt: skip


def _motion(rollout: Rollout) -> np.ndarray | None:
    """The positions of every step, or of evenly spaced steps where a large body's would hold
    more than :data:`MOTION_POSITIONS`; None when the run is unstable."""
    scene = rollout.scene
    count = max(2, MOTION_POSITIONS // scene.num_particles)
    kept = None if count > scene.steps else evenly_spaced(0, scene.steps, count)
    try:
        positions = rollout.simulate(kept=kept)
    except (UnstableSimulation, torch.linalg.LinAlgError):
        return None
    return positions if np.isfinite(positions).all() else None
