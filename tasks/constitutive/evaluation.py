"""Scoring one captured law: rebuild it from its graph, fit it through the simulator, report.

Trusted: it never runs a candidate's code, only the checked graph the capture recorded
(:mod:`tasks.constitutive.law_graph`). Imports Taichi and torch, so it is imported only where a
candidate is fitted (the fit worker, tests), never when the search lists tasks.
"""

from __future__ import annotations

import contextlib
import io
import math
import time
from collections.abc import Iterator
from typing import Any

import torch

import taichi_mpm as tm
from bridges import laws as torch_laws
from bridges import products
from bridges.rollout import LawError, Rollout, trajectory_loss
from bridges.step import torch_dtype
from sga_agent.task import (
    Evaluation,
    EvaluationSettings,
    is_out_of_memory,
    report_progress,
    selected_device,
)
from taichi_mpm import runtime
from tasks.constitutive import feedback, fidelity, law_kernel
from tasks.constitutive.ground_truth import Trajectory, load_or_generate
from tasks.constitutive.inner import (
    InnerResult,
    InnerSettings,
    NoFiniteEpoch,
    optimize,
    prepare_optimizer,
)
from tasks.constitutive.law_code import describe_error
from tasks.constitutive.law_graph import GraphLaw, LawGraphError, build_law
from tasks.constitutive.options import ConstitutiveOptions
from tasks.constitutive.specs import ELASTIC_TRUTH, KNOWN_ELASTIC, ConstitutiveSpec


def ensure_runtime(precision: str) -> None:
    """Start Taichi on the process's device (:func:`~sga_agent.task.selected_device`: the
    CPU unless ``--device cuda``) unless it runs already (one precision per process), without
    its "[Taichi] Starting on arch=x64" line: in the search's own process (the findings) that
    line would land on the progress bar."""
    try:
        runtime.current()
    except runtime.RuntimeNotInitialized:
        with contextlib.redirect_stdout(io.StringIO()):
            tm.init(arch=selected_device(), precision=precision)


def check_precision(precision: str | None) -> None:
    """``ValueError`` when Taichi runs in this process in a precision other than ``precision``."""
    try:
        running = runtime.current().precision
    except runtime.RuntimeNotInitialized:
        return
    if precision not in (None, running):
        raise ValueError(
            f"option precision={precision} differs from the {running} Taichi running in this "
            "process; leave the option out or evaluate in a fresh process"
        )


def ground_truth(spec: ConstitutiveSpec, steps: int | None = None) -> Trajectory:
    """The task's observed trajectory (cached)."""
    scene = tm.paper_scene(steps=steps or spec.steps)
    return load_or_generate(spec.name, spec.material(), scene, spec.reset_every)


def known_elastic_law(dtype: torch.dtype) -> torch.nn.Module:
    """The fixed elastic law of the plastic tasks, frozen."""
    law = torch_laws.StVKHencky(E=KNOWN_ELASTIC.E, nu=KNOWN_ELASTIC.nu, dtype=dtype)
    return law.requires_grad_(False)


def warm_up(spec: ConstitutiveSpec, options: ConstitutiveOptions) -> Iterator[None]:
    """Pay an evaluation's first-use costs ahead of it, in stages (a generator, see
    :mod:`sga_agent.fit_worker`), the ones every evaluation needs first:

    1. the ground truth, and the bridge's kernels launched with known laws on a few 2-step
       segments that start from the observed reset states (the loss is meaningless): for the
       elastic task a neo-Hookean law, which needs no SVD; for the plastic ones von Mises and
       the known elastic law, whose Hencky stress every evaluation runs;
    2. for the elastic task, the same with von Mises and the Hencky stress (a law may use an
       SVD);
    3. the inner optimizer and the batched products a captured law may use
       (:func:`warm_up_fitting`).

    Kernels are launched as an evaluation launches them: one scene copy forward (the
    graph-memory measurement), a batch of copies forward and backward (the epochs). A copy
    alone backward (no teacher forcing, or a short last segment) is left to compile when
    first needed: Taichi runs its Python front end on each kernel in every process, even when
    its offline cache has it."""
    ensure_runtime(options.precision or "float32")
    dtype = torch_dtype()
    observed = ground_truth(spec, options.steps)
    report_progress("warming up: compiling the simulator's kernels")
    segments, segment = min(len(observed.states["x"]), 5), 2
    steps = min(segments * segment, observed.positions.shape[0] - 1)
    scene = tm.paper_scene(steps=steps)

    def launch(plastic: torch.nn.Module, elastic: torch.nn.Module) -> None:
        rollout = Rollout(scene, plastic, elastic)
        for batch, backward in ((1, False), (segments, True)):
            trajectory_loss(rollout, observed.positions[: steps + 1], observed.states, segment,
                            backward=backward, batch=batch)  # fmt: skip

    if spec.searched == "elastic":
        launch(torch_laws.NoPlasticity(), torch_laws.NeoHookean(**ELASTIC_TRUTH, dtype=dtype))
        yield
    launch(torch_laws.VonMises(yield_stress=KNOWN_ELASTIC.E * 1e-3, E=KNOWN_ELASTIC.E,
                               nu=KNOWN_ELASTIC.nu, dtype=dtype),
           known_elastic_law(dtype))  # fmt: skip
    yield
    warm_up_fitting(dtype, options.optimizer or spec.optimizer)


def warm_up_fitting(dtype: torch.dtype, optimizer: str) -> None:
    """Pay the inner fit's first-use costs that no law changes: its ``optimizer`` (see
    :func:`~tasks.constitutive.inner.prepare_optimizer`) and the batched products' kernels."""
    prepare_optimizer(optimizer)
    products.compile_kernels(dtype)


def fit(
    rollout: Rollout, law: torch.nn.Module, observed: Trajectory, inner: InnerSettings,
    started: float,
) -> InnerResult | Evaluation:
    """The inner optimization's result, or the invalid :class:`Evaluation` that says why the
    law could not be fitted (``started``: when the evaluation began, for its duration)."""
    try:
        return optimize(rollout, law, observed, inner)
    except LawError as error:
        return Evaluation.invalid(str(error), seconds=time.perf_counter() - started)
    except NoFiniteEpoch as error:
        return Evaluation.invalid(
            f"the simulation is unstable with this law ({error})",
            status="unstable",
            seconds=time.perf_counter() - started,
        )
    except Exception as error:  # a law failing inside forward, e.g. a shape mismatch
        return Evaluation.invalid(
            f"the law raised {describe_error(error)} during the simulation",
            status="out_of_memory" if is_out_of_memory(error) else "error",
            seconds=time.perf_counter() - started,
        )


def evaluate(spec: ConstitutiveSpec, data: Any, settings: EvaluationSettings) -> Evaluation:
    """Fit the captured law ``data`` (``{"law": graph}``) to the task's observation.

    Invalid results carry a reason. ``settings.options`` is a
    :class:`~tasks.constitutive.options.ConstitutiveOptions` (None: its defaults). A
    ``settings.fidelity`` below 1 fits fewer epochs on the first segments only
    (:mod:`tasks.constitutive.fidelity`); the extras record the fidelity, epochs and segments.
    """
    started = time.perf_counter()
    options = settings.options_as(ConstitutiveOptions)
    check_precision(options.precision)
    ensure_runtime(options.precision or "float32")
    dtype = torch_dtype()
    try:
        law = build_law(data.get("law") if isinstance(data, dict) else None, dtype)
    except LawGraphError as error:
        return Evaluation.invalid(str(error), seconds=time.perf_counter() - started)
    observed = ground_truth(spec, options.steps)
    compile_law(law, observed, options, settings.fidelity)
    observed = fidelity.first_segments(observed, spec.reset_every, settings.fidelity)
    rollout = task_rollout(spec, law, tm.paper_scene(steps=observed.positions.shape[0] - 1))
    inner = InnerSettings(
        epochs=fidelity.screen_epochs(
            spec.epochs if settings.epochs is None else settings.epochs, settings.fidelity
        ),
        learning_rate=settings.learning_rate or spec.learning_rate,
        reset_every=spec.reset_every,
        optimizer=options.optimizer or spec.optimizer,
        graph_memory_mb=options.graph_memory_mb,
        batch_particles=options.batch_particles,
    )
    result = fit(rollout, law, observed, inner, started)
    if isinstance(result, Evaluation):
        return result
    corners = feedback.corner_particles(observed.positions[0])
    text = "\n\n".join(
        [
            feedback.optimization_text(result, inner),
            feedback.trajectory_text(result.positions, observed.positions, rollout.scene.dt,
                                     corners),
        ]
    )
    evaluation = fitted_evaluation(result, text, started)
    evaluation.extras.update(fidelity=settings.fidelity, epochs=inner.epochs,
                             segments=fidelity.segments(observed, spec.reset_every))  # fmt: skip
    return evaluation


def compile_law(law: GraphLaw, observed: Trajectory, options: ConstitutiveOptions,
                fidelity: float = 1.0) -> None:  # fmt: skip
    """Give ``law`` (built in the running Taichi's precision) its Taichi kernels where
    ``options.law_kernels`` asks for them (for a fit at ``fidelity``: see
    :func:`law_kernels_for`) and the translation agrees with torch on the observation's
    deformation gradients."""
    kernels = law_kernels_for(options.law_kernels, fidelity)
    if kernels == "none":
        return
    report_progress("compiling the law")
    F = observed_deformations(observed, torch_dtype())
    svd, factored = kernels == "all", kernels == "svd-inputs"
    law.use_kernels(law_kernel.kernel_law(law, F, svd=svd, factored=factored))


def law_kernels_for(option: str, fidelity: float) -> str:
    """The ``law_kernels`` mode of a fit at ``fidelity``: ``auto`` is ``all`` for a full fit
    and ``no-svd`` for a screen (below 1), a fit too short to repay the compiling of an SVD's
    sweeps (about 0.75 s against its one epoch on two segments); any other option as it is."""
    if option != "auto":
        return option
    return "all" if fidelity >= 1.0 else "no-svd"


def task_rollout(spec: ConstitutiveSpec, law: torch.nn.Module, scene: tm.Scene) -> Rollout:
    """``scene`` with the searched ``law`` in its place: the elastic law without plasticity, or
    the plastic law beside the known elastic one."""
    if spec.searched == "elastic":
        return Rollout(scene, torch_laws.NoPlasticity(), law)
    return Rollout(scene, law, known_elastic_law(torch_dtype()))


def observed_deformations(observed: Trajectory, dtype: torch.dtype) -> torch.Tensor:
    """Deformation gradients of the observation (its reset states), to check a compiled law on;
    near-identity ones where it has none."""
    if observed.states is not None:
        return torch.as_tensor(observed.states["F"], dtype=dtype).reshape(-1, 3, 3)
    noise = torch.randn(1000, 3, 3, generator=torch.Generator().manual_seed(0), dtype=dtype)
    return torch.eye(3, dtype=dtype) + 0.05 * noise


def fitted_evaluation(result: InnerResult, feedback_text: str, started: float) -> Evaluation:
    """The Evaluation of a finished fit: its best epoch's loss and parameters and the curves;
    ``started`` is when it began."""
    return Evaluation(
        valid=math.isfinite(result.best_loss),
        loss=result.best_loss,
        feedback=feedback_text,
        parameters=result.best_parameters,
        curves={"loss": result.losses, **result.parameters},
        extras={
            "best_epoch": result.best_epoch,
            "stopped": result.stopped,
            "epoch_seconds": result.seconds,
        },  # fmt: skip
        seconds=time.perf_counter() - started,
    )
