"""The inner optimization: fit a law's continuous parameters to the observed trajectory.

Adam on every trainable parameter of the searched law, the gradient norm clipped, one epoch
being one teacher-forced rollout of the whole scene (forward and segment-wise backward). The
parameters of the best epoch are kept. A non-finite loss or gradient stops the optimization
with its reason; what was found before it stands.
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass, field

import numpy as np
import torch
from torch import nn

from bridges.rollout import Rollout, UnstableSimulation, trajectory_loss
from tasks.constitutive.ground_truth import Trajectory


@dataclass(frozen=True)
class InnerSettings:
    """Paper defaults: Adam, learning rate 3e-2, 30 epochs, gradient norm clipped to 1."""

    epochs: int = 30
    learning_rate: float = 3e-2
    clip_norm: float = 1.0
    reset_every: int = 100


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

    ``settings.epochs`` gradient steps are taken and the parameters after the last one are
    scored too; a law without trainable parameters is scored once.

    Raises
    ------
    NoFiniteEpoch
        The starting parameters already make the simulation non-finite.
    """
    trainable = [p for p in law.parameters() if p.requires_grad]
    optimizer = torch.optim.Adam(trainable, lr=settings.learning_rate) if trainable else None
    epochs = settings.epochs if trainable else 0
    result = InnerResult(parameters={name: [] for name in scalar_parameters(law)})
    best_state = copy.deepcopy(law.state_dict())
    for epoch in range(epochs + 1):
        last = epoch == epochs
        started = time.perf_counter()
        if optimizer is not None:
            optimizer.zero_grad(set_to_none=True)
        try:
            run = trajectory_loss(
                rollout, observed.positions, observed.states, settings.reset_every,
                backward=not last,
            )  # fmt: skip
        except UnstableSimulation as error:
            result.stopped = f"epoch {epoch}: {error}"
            break
        result.losses.append(run.loss)
        for name, value in scalar_parameters(law).items():
            result.parameters[name].append(value)
        if run.loss < result.best_loss:
            result.best_epoch, result.best_loss, result.positions = epoch, run.loss, run.positions
            best_state = copy.deepcopy(law.state_dict())
        if last:
            result.seconds.append(time.perf_counter() - started)
            break
        bad = _non_finite_gradient(law)
        if bad:
            result.stopped = f"epoch {epoch}: the gradient of {bad} is not finite"
            break
        torch.nn.utils.clip_grad_norm_(trainable, settings.clip_norm)
        optimizer.step()
        result.seconds.append(time.perf_counter() - started)
    if result.best_epoch < 0:
        raise NoFiniteEpoch(result.stopped or "no epoch gave a finite loss")
    law.load_state_dict(best_state)
    return result


def _non_finite_gradient(law: nn.Module) -> str:
    for name, parameter in law.named_parameters():
        if parameter.grad is not None and not torch.isfinite(parameter.grad).all():
            return name
    return ""
