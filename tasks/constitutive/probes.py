"""Probe scenes: experiments no run was fitted to, where laws that fit one observation equally
well may part (:meth:`sga_agent.task.TaskBase.compare_forms`).

Four probes, each a body on the training scene's grid, time step, walls, density and gravity,
for :data:`DURATION`: a stronger impact, a stretch, a shear and a collapse under its own weight.
They load a body in ways one observation of a thrown body may not (large compression and
tension, shear, slow gravity-driven flow), and none of them is the held-out scene, which judges
the best law and must stay unseen by anything that chooses it.

Trusted: the laws simulated here are rebuilt from captured graphs.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import taichi_mpm as tm
from sga_agent.task import Probe

#: How long each probe runs (s).
DURATION = 0.15
#: The impact's downward speed (m/s), the stretch's rate along x (1/s; half of it squeezes y and
#: z), the shear's velocity gradient (1/s).
IMPACT_SPEED, STRETCH_RATE, SHEAR_RATE = 5.0, 3.0, 4.0


@dataclass(frozen=True)
class ProbeScene:
    """A probe in words (:class:`~sga_agent.task.Probe`) and the scene it simulates."""

    probe: Probe
    scene: tm.Scene


def probe_scenes(
    base: tm.Scene, body: np.ndarray, volume: float, body_text: str, duration: float = DURATION
) -> list[ProbeScene]:
    """The probes of a body (``body``: its particles' positions, (N, 3); ``volume``: one
    particle's volume; ``body_text``: the body in words, "a cube of side 0.3 m") set up like
    ``base``, each ``duration`` seconds long. A probe whose body does not fit the domain is
    left out."""
    steps = max(1, round(duration / base.dt))
    floor = base.walls.thickness * base.dx
    middle = base.domain_size / 2
    centred = body - body.mean(axis=0) + middle
    resting = centred + [0.0, floor + base.dx - centred[:, 1].min(), 0.0]
    offset = centred - middle
    zero = np.zeros_like(body)
    shear = np.stack([SHEAR_RATE * offset[:, 1], zero[:, 1], zero[:, 2]], axis=1)
    stretch = offset * [STRETCH_RATE, -STRETCH_RATE / 2, -STRETCH_RATE / 2]
    impact = zero + [0.0, -IMPACT_SPEED, 0.0]
    setups = [
        ("a stronger impact", resting, impact,
         f"thrown straight down at {IMPACT_SPEED:g} m/s from one cell above the floor"),
        ("a stretch", centred, stretch,
         f"stretched along x at {STRETCH_RATE:g} /s and squeezed along y and z at "
         f"{STRETCH_RATE / 2:g} /s, in mid-air"),
        ("a shear", centred, shear,
         f"sheared in mid-air: its x-velocity {SHEAR_RATE:g} /s times the height above its "
         "centre"),
        ("a collapse under its own weight", resting, zero,
         "at rest one cell above the floor, left to fall and settle"),
    ]  # fmt: skip
    setting = (f"for {steps * base.dt:g} s ({steps} steps of {base.dt:g} s) on the training "
               "scene's grid, walls and gravity")  # fmt: skip
    probes = []
    for name, positions, velocities, motion in setups:
        try:
            scene = dataclasses.replace(base, positions=positions, velocities=velocities,
                                        particle_volume=volume, steps=steps)  # fmt: skip
        except tm.SceneError:
            continue  # the body does not fit there
        probes.append(ProbeScene(Probe(name, f"{body_text} {motion}, {setting}"), scene))
    return probes


def spread(motions: Sequence[np.ndarray | None], body_size: float) -> float:
    """The largest distance between two of ``motions`` (positions of every step, (steps + 1,
    N, 3); None for an unstable run) at any step, RMS over particles, in ``body_size``: inf
    when some but not all are unstable, nan when all are."""
    stable = [motion for motion in motions if motion is not None]
    if not stable:
        return math.nan
    if len(stable) < len(motions):
        return math.inf
    largest = 0.0
    for index, first in enumerate(stable):
        for second in stable[index + 1 :]:
            distance = np.sqrt(((first - second) ** 2).sum(axis=-1).mean(axis=-1)).max()
            largest = max(largest, float(distance) / body_size)
    return largest


def probe_spreads(
    laws: Sequence[object],
    probes: Sequence[ProbeScene],
    simulate: Callable[[object, tm.Scene], np.ndarray | None],
) -> dict[str, float]:
    """Each probe's :func:`spread` of ``laws`` simulated by ``simulate(law, scene)``."""
    spreads = {}
    for probe in probes:
        size = float(np.ptp(probe.scene.positions, axis=0).max())
        spreads[probe.probe.name] = spread([simulate(law, probe.scene) for law in laws], size)
    return spreads


def written(probe: ProbeScene, folder: Path | None) -> Probe:
    """``probe``'s words with the file its scene was written to (``folder/probes/NAME.npz``;
    the words alone without a folder or when it cannot be written)."""
    if folder is None:
        return probe.probe
    name = re.sub(r"[^a-z]+", "-", probe.probe.name.lower()).strip("-")
    try:
        (folder / "probes").mkdir(parents=True, exist_ok=True)
        path = tm.save_scene(folder / "probes" / f"{name}.npz", probe.scene)
    except OSError:
        return probe.probe
    return dataclasses.replace(probe.probe, file=str(path))
