"""Compile every kernel once, so that later processes load them from Taichi's offline cache.

Taichi compiles a kernel the first time it runs; the reverse-mode kernels take a few
minutes in all on a 2-core CPU. :func:`warm_up` runs each built-in law forward and
backward on a tiny scene, which fills the offline cache (``~/.cache/taichi``) for the
current architecture and precision. ``taichi-mpm warmup`` does it from the shell.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np

from taichi_mpm import runtime
from taichi_mpm.materials import (
    DruckerPrager,
    FixedCorotated,
    LinearElastic,
    Material,
    NeoHookean,
    NoPlasticity,
    PlasticMixture,
    StVKHencky,
    VonMises,
    WeaklyCompressibleFluid,
)
from taichi_mpm.scene import Scene, cube
from taichi_mpm.simulator import Simulator

#: Together these use every constitutive kernel, with and without a shared SVD.
WARM_UP_MATERIALS = (
    Material(LinearElastic(E=1e4, nu=0.3), NoPlasticity()),
    Material(FixedCorotated(E=1e4, nu=0.3), VonMises(yield_stress=1e3)),
    Material(NeoHookean(E=1e4, nu=0.3), DruckerPrager(friction_angle=30.0)),
    Material(
        StVKHencky(E=1e4, nu=0.3),
        PlasticMixture(
            (
                (0.4, NoPlasticity()),
                (0.2, VonMises(1e3)),
                (0.2, DruckerPrager(30.0)),
                (0.2, WeaklyCompressibleFluid()),
            )
        ),
    ),
)


def warm_up(parallel: tuple[bool, ...] = (False, True)) -> float:
    """Compile the forward and reverse kernels of every law; returns the seconds taken.

    ``parallel`` selects the loop variants to compile (serial: small scenes on the CPU,
    parallel: large scenes and GPUs).
    """
    start = time.perf_counter()
    for _ in warm_up_passes(parallel):
        pass
    return time.perf_counter() - start


def warm_up_passes(parallel: tuple[bool, ...] = (False, True)) -> Iterator[str]:
    """:func:`warm_up` one pass at a time: yields what the next pass is ("FixedCorotated +
    VonMises, serial loops, backward"), then compiles (or loads) and runs it when asked for the
    following one; two passes (forward, backward) per law and loop variant."""
    runtime.current()
    positions, volume = cube((0.5, 0.5, 0.5), 0.2, 2)
    scene = Scene(positions, np.zeros_like(positions), volume, grid_resolution=8, steps=2)
    for mode in parallel:
        loops = "parallel loops" if mode else "serial loops"
        for material in WARM_UP_MATERIALS:
            law = f"{type(material.elastic).__name__} + {type(material.plastic).__name__}"
            yield f"{law}, {loops}, forward"
            sim = Simulator(scene, material, parallel=mode)
            recorded = sim.forward([scene.steps])
            yield f"{law}, {loops}, backward"
            sim.backward(np.ones_like(recorded))
