"""The inner optimization: fit a law's continuous parameters to the observed trajectory.

Adam on every trainable parameter of the searched law, the gradient norm clipped, one epoch
being one teacher-forced rollout of the whole scene (forward and segment-wise backward). The
parameters of the best epoch are kept. A non-finite loss or gradient stops the optimization
with its reason; what was found before it stands. Each finished epoch is reported
(:func:`~sga_agent.task.report_progress`: "fitting", epoch i of N, its loss).
"""

from __future__ import annotations

import contextlib
import copy
import math
import time
from dataclasses import dataclass, field

import numpy as np
import torch
from torch import nn

from bridges.linalg import stable_linalg
from bridges.rollout import (
    Rollout,
    State,
    UnstableSimulation,
    segments_per_batch,
    trajectory_loss,
)
from sga_agent.task import release_freed_memory, report_progress
from tasks.constitutive.adam import Adam
from tasks.constitutive.ground_truth import Trajectory

#: Inner optimizers: ``InnerSettings.optimizer``.
OPTIMIZERS = ("adam", "lbfgs")


@dataclass(frozen=True)
class InnerSettings:
    """Paper defaults: Adam, learning rate 3e-2, 30 epochs, gradient norm clipped to 1.

    ``optimizer="lbfgs"`` uses L-BFGS with a strong-Wolfe line search instead: every epoch is
    one loss-and-gradient evaluation (a line search may take several); ``learning_rate`` and
    ``clip_norm`` are unused (its steps come from the line search).

    The teacher-forced segments of an epoch run as batches of scene copies, as many at a time
    as fit ``graph_memory_mb`` of autograd graph (measured on the law at hand; at least one)
    and hold at most ``batch_particles`` particles together.
    Without reset states (``Trajectory.states`` None) ``reset_every`` is the length of the
    checkpointed segments the gradient is carried across.
    """

    epochs: int = 30
    learning_rate: float = 3e-2
    clip_norm: float = 1.0
    reset_every: int = 100
    optimizer: str = "adam"
    graph_memory_mb: float = 120.0
    batch_particles: int = 5_000

    def __post_init__(self) -> None:
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(
                f"unknown inner optimizer {self.optimizer!r}; choose one of {', '.join(OPTIMIZERS)}"
            )


@dataclass
class InnerResult:
    """Loss and parameter values per epoch (before that epoch's update) and the best epoch."""

    losses: list[float] = field(default_factory=list)
    parameters: dict[str, list[float]] = field(default_factory=dict)
    best_epoch: int = -1
    best_loss: float = math.inf
    positions: np.ndarray | None = None  # predicted positions at the best epoch
    seconds: list[float] = field(default_factory=list)  # wall time of each epoch
    stopped: str = ""  # why the optimization ended early ("" when it ran every epoch)
    unused: list[str] = field(default_factory=list)  # parameters the law's output ignores
    rejected_trials: list[str] = field(default_factory=list)  # L-BFGS trial points that failed

    @property
    def best_parameters(self) -> dict[str, float]:
        return {name: values[self.best_epoch] for name, values in self.parameters.items()}


class NoFiniteEpoch(FloatingPointError):
    """Not even the starting parameters give a finite loss."""


def scalar_parameters(law: nn.Module) -> dict[str, float]:
    """Every trainable parameter as scalars: ``name`` or ``name[i]`` for tensors."""
    values: dict[str, float] = {}
    for name, parameter in law.named_parameters():
        if not parameter.requires_grad:
            continue
        flat = parameter.detach().reshape(-1).tolist()
        if len(flat) == 1:
            values[name] = flat[0]
        else:
            values.update({f"{name}[{i}]": value for i, value in enumerate(flat)})
    return values


def optimize(
    rollout: Rollout, law: nn.Module, observed: Trajectory, settings: InnerSettings
) -> InnerResult:
    """Fit ``law`` (one of ``rollout``'s laws) to ``observed``; leaves the best values in it.

    Adam takes ``settings.epochs`` gradient steps and the parameters after the last one are
    scored too; L-BFGS gets ``settings.epochs + 1`` evaluations. A law without trainable
    parameters is scored once. Parameters the law's output does not depend on are frozen
    (not fitted) and named in ``unused`` (see :func:`unused_parameters`).

    Raises
    ------
    NoFiniteEpoch
        The starting parameters already make the simulation non-finite.
    """
    unused = unused_parameters(law)
    for name, parameter in law.named_parameters():
        if name in unused:
            parameter.requires_grad_(False)  # no gradient can reach it
    trainable = [p for p in law.parameters() if p.requires_grad]
    once = not trainable or settings.epochs == 0
    fit = _Fit(rollout, law, observed, settings, total=1 if once else settings.epochs + 1)
    fit.result.unused = unused
    report_progress("fitting", *fit.progress())
    if once:
        if fit.score(backward=False) is None:
            fit.result.stopped = fit.failure
    elif settings.optimizer == "lbfgs":
        _lbfgs(fit, trainable, settings.epochs + 1)
    else:
        _adam(fit, trainable, settings)
    if fit.result.best_epoch < 0:
        raise NoFiniteEpoch(fit.result.stopped or "no epoch gave a finite loss")
    law.load_state_dict(fit.best_state)
    return fit.result


def unused_parameters(law: nn.Module) -> list[str]:
    """Names of the trainable parameters no gradient of the law's output reaches (never used
    in ``forward``, or only in a comparison), tried on two deformation gradients near I.

    A law that fails on them is left to the fit to report: the answer is then empty.
    """
    named = [(name, p) for name, p in law.named_parameters() if p.requires_grad]
    if not named:
        return []
    dtype = named[0][1].dtype
    F = torch.eye(3, dtype=dtype) + 0.01 * torch.arange(18, dtype=dtype).reshape(2, 3, 3).sin()
    try:
        with stable_linalg():
            output = law(F)
            if not (isinstance(output, torch.Tensor) and output.requires_grad):
                return [name for name, _ in named]
            grads = torch.autograd.grad(output.sum(), [p for _, p in named], allow_unused=True)
    except Exception:  # the law's own failure: the fit reports it
        return []
    return [name for (name, _), grad in zip(named, grads, strict=True) if grad is None]


class _Fit:
    """Scores the law's current parameters, one epoch each (of at most ``total``), and remembers
    the best."""

    def __init__(
        self,
        rollout: Rollout,
        law: nn.Module,
        observed: Trajectory,
        settings: InnerSettings,
        total: int,
    ) -> None:
        self.rollout, self.law, self.observed, self.settings = rollout, law, observed, settings
        self.total = total
        self.result = InnerResult(parameters={name: [] for name in scalar_parameters(law)})
        self.best_state = copy.deepcopy(law.state_dict())
        self.failure = ""  # why the last score was None
        self.batch = 0  # segments per batch: measured on the first backward epoch

    @property
    def epochs_done(self) -> int:
        return len(self.result.losses)

    def progress(self, epoch: int | None = None) -> tuple[int | None, int | None]:
        """Epoch ``epoch`` (0: the starting values) of the fit's epochs, as progress notes
        count them: the settings' epochs, none when the law is only scored."""
        return (epoch, self.total - 1) if self.total > 1 else (None, None)

    def score(self, backward: bool) -> float | None:
        """The loss (gradients in ``.grad`` if ``backward``); None, with the reason in
        ``failure``, when the simulation or the gradient is not finite."""
        started = time.perf_counter()
        epoch = self.epochs_done
        release_freed_memory()  # the last epoch's graph: so this one reuses, not adds, memory
        try:
            observed = self.observed
            if observed.states is None:  # no teacher forcing: checkpointed segments
                batch = 1
            elif backward:
                self.batch = self.batch or segments_at_once(self.rollout, observed, self.settings)
                batch = self.batch
            else:
                batch = len(observed.states["x"])
            run = trajectory_loss(
                self.rollout, observed.positions, observed.states, self.settings.reset_every,
                backward=backward, batch=batch,
            )  # fmt: skip
        except UnstableSimulation as error:
            self.failure = f"epoch {epoch}: {error}"
            return None
        result = self.result
        result.losses.append(run.loss)
        for name, value in scalar_parameters(self.law).items():
            result.parameters[name].append(value)
        if run.loss < result.best_loss:
            result.best_epoch, result.best_loss, result.positions = epoch, run.loss, run.positions
            self.best_state = copy.deepcopy(self.law.state_dict())
        result.seconds.append(time.perf_counter() - started)
        report_progress("fitting", *self.progress(epoch), run.loss)
        bad = _non_finite_gradient(self.law) if backward else ""
        if bad:
            self.failure = f"epoch {epoch}: the gradient of {bad} is not finite"
            return None
        return run.loss


def segments_at_once(rollout: Rollout, observed: Trajectory, settings: InnerSettings) -> int:
    """Teacher-forced segments a fit of ``observed`` (with reset states) runs as one batch:
    as many as ``settings.graph_memory_mb`` of graph holds, measured on the rollout's laws from
    the first reset state, and no more than ``settings.batch_particles`` particles; at least 1."""
    start = State.from_arrays(observed.states, 0, rollout.dtype)
    rollout.check_laws(start)  # a law of the wrong shape is reported as such
    budget = int(settings.graph_memory_mb * 2**20)
    fitting = segments_per_batch(rollout, start, settings.reset_every, budget)
    allowed = settings.batch_particles // rollout.scene.num_particles
    return max(1, min(fitting, allowed))


def prepare_optimizer(name: str) -> None:
    """Pay the first use of inner optimizer ``name`` ahead of the first evaluation: L-BFGS
    comes from ``torch.optim``, whose first optimizer in a process imports torch's compiler
    stack (``torch._dynamo``), about a second on this CPU; Adam is :mod:`.adam`'s and needs
    nothing."""
    if name == "lbfgs":
        torch.optim.LBFGS([torch.zeros(1, requires_grad=True)])


def _adam(fit: _Fit, trainable: list[nn.Parameter], settings: InnerSettings) -> None:
    optimizer = Adam(trainable, lr=settings.learning_rate)
    for epoch in range(settings.epochs + 1):
        last = epoch == settings.epochs
        optimizer.zero_grad()
        if fit.score(backward=not last) is None:
            fit.result.stopped = fit.failure
            return
        if last:
            return
        torch.nn.utils.clip_grad_norm_(trainable, settings.clip_norm)
        optimizer.step()


class _Stop(Exception):
    """Ends an L-BFGS step from inside its closure."""


#: Objective (in units of the first loss) an L-BFGS trial point that makes the simulation or the
#: gradient non-finite counts as, so the line search steps back instead of stopping.
REJECTED_TRIAL_LOSS = 1e3
#: Rejected trial points after which L-BFGS gives up.
MAX_REJECTED_TRIALS = 5


def _lbfgs(fit: _Fit, trainable: list[nn.Parameter], evaluations: int) -> None:
    # Losses and gradients are tiny (1e-6 and below): the objective is scaled by the first loss
    # and no tolerance may stop it early.
    optimizer = torch.optim.LBFGS(
        trainable, lr=1.0, max_iter=evaluations, max_eval=evaluations, history_size=10,
        tolerance_grad=0.0, tolerance_change=0.0, line_search_fn="strong_wolfe",
    )  # fmt: skip
    scale: list[float] = []  # the first loss: the objective is loss / scale, of order one
    rejected: list[str] = []  # why trial points failed

    def closure() -> torch.Tensor:
        if fit.epochs_done + len(rejected) >= evaluations:
            raise _Stop
        optimizer.zero_grad(set_to_none=True)
        loss = fit.score(backward=True)
        if loss is None:
            if not scale:
                fit.result.stopped = fit.failure  # the start itself failed
                raise _Stop
            rejected.append(fit.failure)
            if len(rejected) >= MAX_REJECTED_TRIALS:
                fit.result.stopped = (
                    f"{len(rejected)} rejected trial points, the last at {rejected[-1]}"
                )
                raise _Stop
            optimizer.zero_grad(set_to_none=True)  # a partial backward may have run
            return torch.tensor(REJECTED_TRIAL_LOSS, dtype=torch.float64)
        if not scale:
            scale.append(loss if loss > 0 else 1.0)
        for parameter in trainable:
            if parameter.grad is not None:
                parameter.grad.div_(scale[0])
        return torch.tensor(loss / scale[0], dtype=torch.float64)

    with contextlib.suppress(_Stop):
        optimizer.step(closure)
    fit.result.rejected_trials = rejected


def _non_finite_gradient(law: nn.Module) -> str:
    for name, parameter in law.named_parameters():
        if parameter.grad is not None and not torch.isfinite(parameter.grad).all():
            return name
    return ""
