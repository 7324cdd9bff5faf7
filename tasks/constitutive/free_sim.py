"""A fitted law simulated on its own, without teacher forcing, against an observed trajectory.

Trusted: the law is rebuilt from its captured graph (:func:`fitted_law`) or is one of ours
(:func:`bridges.laws.from_material`); no candidate code runs here.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch

import taichi_mpm as tm
from bridges.rollout import UnstableSimulation, trajectory_loss
from taichi_mpm.frames import evenly_spaced
from tasks.constitutive.evaluation import task_rollout
from tasks.constitutive.free_run import FreeRun
from tasks.constitutive.law_graph import build_law
from tasks.constitutive.specs import ConstitutiveSpec

#: Frames of a free run kept for reports (the first and the last included).
FRAMES = 31


def fitted_law(graph: Any, parameters: dict[str, float], dtype: torch.dtype) -> torch.nn.Module:
    """The law rebuilt from its captured graph, its parameters set to the fitted values
    (``name`` or ``name[i]`` for an element of a tensor parameter, as the fit records them)."""
    return with_values(build_law(graph, dtype), parameters)


def with_values(law: torch.nn.Module, parameters: dict[str, float]) -> torch.nn.Module:
    """``law`` with the ``parameters`` it has set (others keep their values), frozen."""
    with torch.no_grad():
        for name, parameter in law.named_parameters():
            flat = parameter.view(-1)
            for index in range(flat.numel()):
                key = name if flat.numel() == 1 else f"{name}[{index}]"
                if key in parameters:
                    flat[index] = parameters[key]
    return law.requires_grad_(False)


def free_run_in(
    spec: ConstitutiveSpec, law: torch.nn.Module, scene: tm.Scene, observed: np.ndarray
) -> FreeRun:
    """``law`` in the searched place of ``spec`` (the known elastic law beside a plastic one),
    simulated through ``scene`` from its initial state, against the ``observed`` positions
    (steps + 1, N, 3).

    The error of a step is the root mean square over particles of the distance between
    simulated and observed positions, divided by the body's size (the largest side of its
    initial bounding box). An unstable law gives infinite errors.
    """
    rollout = task_rollout(spec, law, scene)
    size = float(np.ptp(observed[0], axis=0).max())
    frames = evenly_spaced(0, scene.steps, FRAMES)
    try:
        result = trajectory_loss(rollout, observed, None, spec.reset_every, backward=False)
    except UnstableSimulation as error:
        return FreeRun(math.inf, math.inf, size, scene.steps, unstable=str(error))
    errors = np.sqrt(((result.positions - observed) ** 2).sum(axis=-1).mean(axis=-1)) / size
    return FreeRun(
        final_error=float(errors[-1]), mean_error=float(errors.mean()), body_size=size,
        steps=scene.steps, frames=frames.tolist(), positions=result.positions[frames],
        observed=observed[frames],
    )  # fmt: skip
