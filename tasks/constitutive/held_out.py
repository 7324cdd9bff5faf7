"""The held-out scene of the constitutive tasks: another body, thrown otherwise, for longer or
shorter, simulated by the same ground-truth material and cached like the training observation.

A law is fitted on the paper scene (:func:`taichi_mpm.paper_scene`: a cube of side 0.5,
1000 particles, 1000 steps); how well it generalizes is its free run (no teacher forcing)
here, where it was never fitted. :func:`held_out_error` is what the assessment of a run's best
law and a benchmark's floor (the true law, its constants fitted) both call.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

import taichi_mpm as tm
from bridges.step import torch_dtype
from tasks.constitutive.evaluation import ensure_runtime
from tasks.constitutive.free_run import FreeRun
from tasks.constitutive.free_sim import fitted_law, free_run_in, with_values
from tasks.constitutive.ground_truth import Trajectory, load_or_generate
from tasks.constitutive.options import ConstitutiveOptions
from tasks.constitutive.specs import ConstitutiveSpec

#: A ball of radius 0.2 m (particles 0.05 m apart, as the paper's cube: 280 of them), its
#: bottom 0.05 m above the floor's wall, thrown down and sideways while spinning, so that it
#: hits the floor within about 50 steps and rolls, bounces or spreads for the rest.
CENTRE, RADIUS, SPACING = (0.45, 0.4, 0.55), 0.2, 0.05
VELOCITY, SPIN = (-0.3, -2.0, 0.5), (-2.0, 1.0, 3.0)
#: Steps of the held-out scene (dt 5e-4 s: 0.3 s) when the training scene has the task's
#: length; a training scene shortened by ``--option steps`` shortens it in proportion.
STEPS = 600


def held_out_steps(spec: ConstitutiveSpec, options: ConstitutiveOptions) -> int:
    """The held-out scene's steps for a run with ``options``."""
    if options.steps is None:
        return STEPS
    return max(1, round(options.steps * STEPS / spec.steps))


def held_out_scene(steps: int = STEPS) -> tm.Scene:
    """The held-out scene: the paper scene's grid, time step, walls and density, another body
    (:data:`CENTRE`, :data:`RADIUS`), velocity (:data:`VELOCITY`, :data:`SPIN`) and length."""
    positions, volume = tm.sphere(CENTRE, RADIUS, SPACING)
    velocities = tm.rigid_velocity(positions, VELOCITY, SPIN)
    paper = tm.paper_scene(steps=1)
    return tm.Scene(
        positions, velocities, volume, density=paper.density,
        grid_resolution=paper.grid_resolution, domain_size=paper.domain_size, dt=paper.dt,
        steps=steps, gravity=paper.gravity, walls=paper.walls,
    )  # fmt: skip


def held_out_truth(spec: ConstitutiveSpec, options: ConstitutiveOptions) -> Trajectory:
    """The ground-truth material's trajectory in the held-out scene (cached; only its initial
    state is kept, as nothing is teacher-forced here)."""
    ensure_runtime(options.precision or "float32")
    scene = held_out_scene(held_out_steps(spec, options))
    return load_or_generate(f"{spec.name}-held-out", spec.material(), scene, scene.steps)


def held_out_error(
    spec: ConstitutiveSpec,
    graph_or_law: Any,
    parameters: dict[str, float],
    options: ConstitutiveOptions,
) -> FreeRun:
    """The free run of a law in the held-out scene, against the ground truth there.

    ``graph_or_law`` is a captured law's graph (a run's candidate: rebuilt, never run as code)
    or a ``torch.nn.Module`` of ours (the true law of :func:`bridges.laws.from_material`, a
    law of ``examples/laws``); ``parameters`` (fitted values, by parameter name as the fit
    records them) are written into it. The errors are RMS position errors in body sizes (the
    largest side of the ball's initial bounding box, 0.35 m), at the end and averaged over
    the steps.
    """
    ensure_runtime(options.precision or "float32")
    dtype = torch_dtype()
    if isinstance(graph_or_law, torch.nn.Module):
        law = with_values(graph_or_law.to(dtype), parameters)
    else:
        law = fitted_law(graph_or_law, parameters, dtype)
    truth = held_out_truth(spec, options)
    scene = held_out_scene(truth.positions.shape[0] - 1)
    run = free_run_in(spec, law, scene, np.asarray(truth.positions))
    run.scene = "held-out scene"
    return run


def true_law(spec: ConstitutiveSpec) -> torch.nn.Module:
    """The searched part of the task's ground truth, in torch (its true values)."""
    from bridges import laws as torch_laws

    plastic, elastic = torch_laws.from_material(spec.material(), torch_dtype())
    return elastic if spec.searched == "elastic" else plastic


def main(names: list[str]) -> None:
    """Print the held-out free-run errors of the true law and of the seed of each task (the
    ground truth generated first where it is not cached), and how long the seed's took."""
    import time

    from tasks.constitutive.law_capture import capture_law
    from tasks.constitutive.specs import SPECS

    options = ConstitutiveOptions()
    ensure_runtime("float32")
    for name in names or list(SPECS):
        spec = SPECS[name]
        truth = held_out_error(spec, true_law(spec), {}, options)
        started = time.perf_counter()
        seed = held_out_error(spec, capture_law(spec.seed), {}, options)
        seconds = time.perf_counter() - started
        print(f"{name}: held-out free-run RMS error at the end (mean): true law "
              f"{truth.final_error:.2g} ({truth.mean_error:.2g}), seed {seed.final_error:.2g} "
              f"({seed.mean_error:.2g}); {truth.steps} steps, float32, the seed's free run "
              f"{seconds:.1f} s")  # fmt: skip


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
