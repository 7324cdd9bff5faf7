"""Scoring a captured law on an observation, and what a report learns about the best one.

Trusted, as :mod:`tasks.constitutive.evaluation`: the law is rebuilt from its checked graph and
fitted with the constitutive tasks' inner optimization, here without teacher forcing (the
observation has positions only): one rollout from the initial state per epoch, its loss the
mean squared error over the observed frames and particles (:class:`bridges.rollout.Frames`:
nothing is held for the steps between frames), the gradient carried back across checkpointed
segments of at most ``segment`` steps, as long as ``graph_memory_mb`` allows for the law at
hand (:func:`bridges.rollout.checkpoint_segment`). The hidden truth beside the observation file is
read by :func:`assess` alone, for reports (and recorded when a run starts, see
:func:`tasks.observed.data.provenance`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from bridges import laws as torch_laws
from bridges.rollout import (
    Frames,
    GraphBudgetError,
    Rollout,
    UnstableSimulation,
    checkpoint_segment,
    trajectory_loss,
)
from bridges.step import torch_dtype
from sga_agent.task import (
    Assessment,
    CandidateRecord,
    Evaluation,
    EvaluationSettings,
    FormComparison,
    Simplified,
)
from taichi_mpm.frames import evenly_spaced
from taichi_mpm.scene import Scene
from taichi_mpm.sysid.families import FAMILIES, material_family
from tasks.constitutive import feedback, forms
from tasks.constitutive.assessment import derived_values
from tasks.constitutive.evaluation import (
    check_precision,
    ensure_runtime,
    fit,
    fitted_evaluation,
    warm_up_fitting,
)
from tasks.constitutive.free_run import FreeRun
from tasks.constitutive.free_sim import fitted_law
from tasks.constitutive.ground_truth import Trajectory
from tasks.constitutive.inner import InnerSettings
from tasks.constitutive.law_graph import LawGraphError, build_law, captured_graph
from tasks.constitutive.probes import probe_scenes
from tasks.constitutive.simplify import simplify
from tasks.constitutive.verdict import verdict
from tasks.observed.data import ObservedData, provenance
from tasks.observed.options import ObservedOptions

EPOCHS, LEARNING_RATE = 30, 3e-2  # the constitutive tasks' inner defaults
#: What a fit's memory grows by per byte of graph and checkpoints counted: the C allocator
#: leaves holes between the tensors a segment keeps (1.20x and 1.85x of the count at 2.7e4
#: particles, ``benchmarks/scale.py``; see docs/benchmarks.md, "Scale").
ALLOCATOR_SLACK = 2.0
#: The verdict when an observed file has changed since the run started.
STALE = ("not judged: the observation (or validation) file has changed since the run started, "
         "so nothing was simulated against it")  # fmt: skip


def known_elastic(options: ObservedOptions, dtype: torch.dtype) -> torch.nn.Module:
    """The given elastic law of a plastic search, frozen."""
    material = material_family(options.elastic, E=options.E, nu=options.nu)
    return torch_laws.from_material(material, dtype)[1].requires_grad_(False)


def rollout_for(
    law: torch.nn.Module, scene: Scene, options: ObservedOptions, dtype: torch.dtype
) -> Rollout:
    """``scene`` (the observed one, a probe) with ``law`` in the searched place."""
    if options.searched == "elastic":
        return Rollout(scene, torch_laws.NoPlasticity(), law)
    return Rollout(scene, law, known_elastic(options, dtype))


def frames(data: ObservedData) -> Frames:
    """The observed frames and particles, as a rollout's loss compares them."""
    return Frames(data.frame_steps, data.positions, data.particles)


def trajectory(data: ObservedData) -> Trajectory:
    """The observation as the inner optimization takes it: its frames, no reset states."""
    return Trajectory(frames(data), np.zeros(0, dtype=np.int64), None)


def gradient_segment(rollout: Rollout, options: ObservedOptions) -> int:
    """The checkpointed segment length of a fit of ``rollout`` (its law's graph measured):
    at most ``options.segment`` steps, within ``options.graph_memory_mb``.

    Raises :class:`~bridges.rollout.GraphBudgetError` naming the options that would let it
    fit."""
    budget = int(options.graph_memory_mb * 2**20)
    try:
        return checkpoint_segment(rollout, rollout.scene.steps, budget, options.segment,
                                  ALLOCATOR_SLACK)[0]  # fmt: skip
    except GraphBudgetError as error:
        raise GraphBudgetError(
            f"{error}: raise it with --option graph_memory_mb=MiB (the fit worker's memory "
            "limit bounds it, --memory-mb), or fit fewer frames with --option frames=N"
        ) from None


def setup(options: ObservedOptions) -> tuple[ObservedData, torch.dtype]:
    """The data and the dtype of a Taichi started in the options' precision."""
    check_precision(options.precision)
    ensure_runtime(options.precision or "float32")
    return ObservedData.load(options.observation, options.frames), torch_dtype()


def warm_up(options: ObservedOptions) -> Iterator[None]:
    """Two warm-up stages (see :mod:`sga_agent.fit_worker`): the kernels of a checkpointed
    forward and backward pass (two 1-step segments with a von Mises law), then the inner
    optimizer and the batched products, so that evaluations do not pay for them."""
    data, dtype = setup(options)
    elastic = torch_laws.StVKHencky(E=5e4, nu=0.3, dtype=dtype).requires_grad_(False)
    plastic = torch_laws.VonMises(yield_stress=1e3, E=5e4, nu=0.3, dtype=dtype)
    start = np.repeat(data.scene.positions[None], 2, axis=0)  # any positions will do
    trajectory_loss(Rollout(data.scene, plastic, elastic), Frames(np.array([1, 2]), start), None, 1)
    yield
    warm_up_fitting(dtype, options.optimizer or "adam")


def loss_text(data: ObservedData) -> str:
    return (f"mean squared position error over the {len(data.frame_steps)} observed frames and "
            f"{len(data.particles)} observed particles, m^2")  # fmt: skip


def evaluate(data: Any, settings: EvaluationSettings) -> Evaluation:
    """Fit the captured law ``data`` (``{"law": graph}``) to the observation named in
    ``settings.options`` (an :class:`~tasks.observed.options.ObservedOptions`); the artifact
    ``trajectory`` holds the best epoch's positions."""
    started = time.perf_counter()
    options = settings.options_as(ObservedOptions)
    observed, dtype = setup(options)
    try:
        law = build_law(data.get("law") if isinstance(data, dict) else None, dtype)
    except LawGraphError as error:
        return Evaluation.invalid(str(error), seconds=time.perf_counter() - started)
    rollout = rollout_for(law, observed.scene, options, dtype)
    try:
        segment = gradient_segment(rollout, options)
    except GraphBudgetError as error:
        return Evaluation.invalid(str(error), status="out_of_memory",
                                  seconds=time.perf_counter() - started)  # fmt: skip
    except Exception:  # the law fails on its own: the fit below reports how
        segment = options.segment
    inner = InnerSettings(
        epochs=EPOCHS if settings.epochs is None else settings.epochs,
        learning_rate=settings.learning_rate or LEARNING_RATE,
        reset_every=segment,
        optimizer=options.optimizer or "adam",
    )
    result = fit(rollout, law, trajectory(observed), inner, started)
    if isinstance(result, Evaluation):
        return result
    text = "\n\n".join([feedback.optimization_text(result, inner, loss_text(observed)),
                        trajectory_text(result.positions, observed)])  # fmt: skip
    return fitted_evaluation(result, text, started)


def trajectory_text(predicted: np.ndarray, data: ObservedData) -> str:
    """Four observed particles at the corners of the body, simulated (``predicted``: at the
    observed frames and particles) next to observed, at up to ten of the observed frames: the
    rows that disagree most (see :func:`~tasks.constitutive.feedback.position_table`)."""
    start = data.scene.positions[data.particles]
    picks = evenly_spaced(0, len(data.frame_steps) - 1, feedback.TRAJECTORY_FRAMES)
    columns = list(dict.fromkeys(feedback.corner_particles(start)))
    steps = [int(data.frame_steps[pick]) for pick in picks]
    return feedback.position_table(
        "Trajectories of observed particles near the body's corners (x, y, z in m; y points "
        "up), simulated vs observed",
        start[columns],
        [step * data.scene.dt for step in steps],
        predicted[np.ix_(picks, columns)].swapaxes(0, 1),
        data.positions[np.ix_(picks, columns)].swapaxes(0, 1),
    )


def assess(
    artifacts: dict[str, Any] | None,
    parameters: dict[str, float],
    options: ObservedOptions,
    simulate: bool,
    recorded: Mapping[str, Any] | None = None,
) -> Assessment:
    """The hidden truth with its loss scored like a candidate's without fitting, the best
    law's readable values, its free runs on the observation and on the validation file (the
    held-out scene) and the verdict.

    ``recorded`` is what the run recorded at its start (see
    :func:`~tasks.observed.data.provenance`): its truth is the one named; when an observed file
    has changed since, nothing is simulated (the file is no longer what the run was fitted to).
    """
    data, dtype = setup(options)
    now = provenance(options.observation, options.validation)
    truth = now["truth"] if recorded is None else recorded.get("truth")
    found = Assessment(truth=_truth_text(truth) if truth else "")
    if recorded is not None and any(
        recorded.get(key) != now.get(key) for key in ("observation_sha256", "validation_sha256")
    ):
        found.verdict = STALE
        return found
    if truth:
        material = material_family(truth["family"], **truth["parameters"])
        plastic, elastic = torch_laws.from_material(material, dtype)
        rollout = Rollout(data.scene, plastic.requires_grad_(False), elastic.requires_grad_(False))
        found.truth_loss = trajectory_loss(
            rollout, frames(data), None, options.segment, backward=False
        ).loss
    graph = captured_graph(artifacts)
    if graph is None:
        return found
    found.derived = derived_values(graph, parameters)
    if simulate:
        law = fitted_law(graph, parameters, dtype)
        found.free_run = free_run(law, data, options, dtype)
        if options.validation is not None:
            held_out = ObservedData.load(options.validation)
            found.held_out = free_run(law, held_out, options, dtype)
            found.held_out.scene = "held-out scene"
        found.verdict = verdict(found.held_out, found.free_run)
    return found


def _truth_text(truth: Mapping[str, Any]) -> str:
    values = ", ".join(f"{k} = {v:g}" for k, v in truth["parameters"].items())
    return f"{FAMILIES[truth['family']]}; {values} (hidden from the search)"


def free_run(
    law: torch.nn.Module, data: ObservedData, options: ObservedOptions, dtype: torch.dtype
) -> FreeRun:
    """``law`` simulated from the initial state against the observed particles at the observed
    frames: RMS distance per frame in body sizes, at the last frame and averaged."""
    size, steps = data.body_size, data.scene.steps
    rollout = rollout_for(law, data.scene, options, dtype)
    try:
        simulated = rollout.simulate(kept=data.frame_steps)
    except (UnstableSimulation, torch.linalg.LinAlgError) as error:
        return FreeRun(math.inf, math.inf, size, steps, unstable=str(error).splitlines()[0])
    simulated = simulated[:, data.particles]
    if not np.isfinite(simulated).all():
        return FreeRun(math.inf, math.inf, size, steps, unstable="non-finite positions")
    errors = np.sqrt(((simulated - data.positions) ** 2).sum(axis=-1).mean(axis=-1)) / size
    return FreeRun(
        final_error=float(errors[-1]), mean_error=float(errors.mean()), body_size=size,
        steps=steps, frames=data.frame_steps.tolist(), positions=simulated,
        observed=data.positions,
    )  # fmt: skip


def compare_forms(
    candidates: Sequence[CandidateRecord], options: ObservedOptions, folder: Path | None
) -> FormComparison | None:
    """:func:`tasks.constitutive.forms.compare_forms` on the observed body: the probes set up
    like the observation (its grid, walls, gravity, the body's particles); no floor, the best
    fit's loss is the estimate of the observation's noise."""
    data, dtype = setup(options)
    scene = data.scene
    size = float(np.ptp(scene.positions, axis=0).max())
    text = f"the observed body ({scene.num_particles} particles, {size:.2g} m across)"
    probes = probe_scenes(scene, scene.positions, scene.particle_volume, text)
    return forms.compare_forms(candidates, probes,
                               lambda law, probe: rollout_for(law, probe, options, dtype),
                               None, folder)  # fmt: skip


def simplified(candidate: CandidateRecord, options: ObservedOptions) -> Simplified | None:
    """The candidate's law with the terms the observation does not need dropped
    (:func:`tasks.constitutive.simplify.simplify`), each drop scored as the fit scores a law
    (a free rollout against the observed frames, no fitting); the noise is the best loss's."""
    graph = captured_graph(candidate.artifacts())
    if graph is None:
        return None
    data, dtype = setup(options)
    observed = frames(data)

    def loss_of(parameters: dict[str, float]) -> float:
        rollout = rollout_for(fitted_law(graph, parameters, dtype), data.scene, options, dtype)
        return trajectory_loss(rollout, observed, None, options.segment, backward=False).loss

    return simplify(candidate.code, options.searched, candidate.parameters, loss_of)
