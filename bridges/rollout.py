"""Trajectories of torch constitutive laws through the Taichi MPM, with segment-wise backward.

A step applies the plastic law (F_trial -> F), the elastic law (F -> Kirchhoff stress) and
:func:`bridges.step.mpm_step`. :func:`trajectory_loss` compares a simulated trajectory with an
observed one and back-propagates the mean squared position error into the laws' parameters one
segment at a time, so memory holds one segment's graph, never the whole trajectory:

* with ``resets`` (teacher forcing), each segment starts from the observed state, so the
  segments are independent: each is run, scored and differentiated in turn;
* without, the state at each segment start is kept, and the backward pass re-runs the
  segments last to first, carrying dL/d(state) across their boundaries (checkpointing).

Laws run inside :func:`bridges.linalg.stable_linalg`, so ``torch.linalg.svd`` in a law gets
gradients that stay finite for repeated singular values.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from bridges.linalg import stable_linalg
from bridges.step import Transfer, mpm_step
from taichi_mpm.scene import Scene


class LawError(ValueError):
    """A constitutive law returned something the simulator cannot use."""


class UnstableSimulation(FloatingPointError):
    """The trajectory left the finite numbers (at ``step``)."""

    def __init__(self, message: str, step: int) -> None:
        super().__init__(message)
        self.step = step


@dataclass
class State:
    """Particle state: positions, velocities, APIC affine C, trial deformation gradient F."""

    x: torch.Tensor
    v: torch.Tensor
    C: torch.Tensor
    F: torch.Tensor

    @classmethod
    def initial(cls, scene: Scene, dtype: torch.dtype) -> State:
        """The scene's initial state (C = 0, F = I)."""
        N = scene.num_particles
        return cls(
            torch.as_tensor(scene.positions, dtype=dtype),
            torch.as_tensor(scene.velocities, dtype=dtype),
            torch.zeros(N, 3, 3, dtype=dtype),
            torch.eye(3, dtype=dtype).expand(N, 3, 3).contiguous(),
        )

    @classmethod
    def from_arrays(cls, states: dict[str, np.ndarray], index: int, dtype: torch.dtype) -> State:
        """Entry ``index`` of stacked state arrays (as ``taichi_mpm.Simulator.states``)."""
        return cls(*(torch.as_tensor(states[name][index], dtype=dtype) for name in "xvCF"))

    def tensors(self) -> tuple[torch.Tensor, ...]:
        return (self.x, self.v, self.C, self.F)

    def detached(self, requires_grad: bool = False) -> State:
        return State(*(t.detach().clone().requires_grad_(requires_grad) for t in self.tensors()))


@dataclass
class RolloutResult:
    """Mean squared position error and the simulated positions, (steps + 1, N, 3)."""

    loss: float
    positions: np.ndarray


class Rollout:
    """A scene simulated with a torch plastic law and a torch elastic law.

    Parameters
    ----------
    scene : taichi_mpm.Scene
        Grid, time step, walls and initial particles.
    plastic : nn.Module
        ``forward(F_trial) -> F`` on (N, 3, 3) tensors.
    elastic : nn.Module
        ``forward(F) -> Kirchhoff stress`` on (N, 3, 3) tensors.
    transfer : Transfer, optional
        Reuse another rollout's Taichi arrays (same scene size).
    """

    def __init__(
        self, scene: Scene, plastic: nn.Module, elastic: nn.Module, transfer: Transfer | None = None
    ) -> None:
        self.scene = scene
        self.plastic = plastic
        self.elastic = elastic
        self.transfer = transfer if transfer is not None else Transfer(scene)
        self.dtype = self.transfer.dtype

    def step(self, state: State) -> State:
        """One differentiable step."""
        F = self.plastic(state.F)
        stress = self.elastic(F)
        return State(*mpm_step(state.x, state.v, state.C, F, stress, self.transfer))

    def check_laws(self, state: State) -> None:
        """Check that both laws map ``state.F`` to finite (N, 3, 3) tensors.

        Raises :class:`LawError` for a wrong type or shape, :class:`UnstableSimulation` for
        NaN or inf.
        """
        expected = tuple(state.F.shape)
        with torch.no_grad(), stable_linalg():
            F = _checked(self.plastic(state.F), "plastic law", "F_corrected", expected)
            _checked(self.elastic(F), "elastic law", "Kirchhoff stress", expected)

    def run(self, state: State, steps: int, on_step=None) -> State:
        """``steps`` steps from ``state``; ``on_step(step_index, state)`` after each."""
        with stable_linalg():
            for s in range(steps):
                state = self.step(state)
                if on_step is not None:
                    on_step(s + 1, state)
        return state

    def simulate(self, state: State | None = None, steps: int | None = None) -> np.ndarray:
        """Positions of every step, (steps + 1, N, 3), without gradients."""
        state = state or State.initial(self.scene, self.dtype)
        steps = self.scene.steps if steps is None else steps
        positions = [state.x.numpy().copy()]
        with torch.no_grad():
            self.run(state, steps, lambda s, st: positions.append(st.x.numpy().copy()))
        return np.stack(positions)


def trajectory_loss(
    rollout: Rollout,
    observed: torch.Tensor | np.ndarray,
    resets: dict[str, np.ndarray] | None = None,
    segment: int = 100,
    backward: bool = True,
) -> RolloutResult:
    """Mean squared position error against ``observed``, differentiated segment by segment.

    Parameters
    ----------
    rollout : Rollout
        Scene and laws; the gradients accumulate in the laws' parameters' ``.grad``.
    observed : (steps + 1, N, 3)
        Observed positions at every step, from step 0.
    resets : dict of stacked states, optional
        Teacher forcing: entry i (keys x, v, C, F) is the observed state at step
        ``i * segment``; each segment then starts from it. Without, segment 0 starts from the
        scene's initial state and each later one from where the previous one ended.
    segment : int
        Steps per segment.
    backward : bool
        Back-propagate (otherwise only the loss and positions).

    Raises
    ------
    LawError, UnstableSimulation
        A law returned a wrong shape, or the loss became non-finite.
    """
    observed = torch.as_tensor(observed, dtype=rollout.dtype)
    steps = observed.shape[0] - 1
    if steps < 1 or segment < 1:
        raise ValueError("observed needs at least two frames and segment must be >= 1")
    starts = list(range(0, steps, segment))
    if resets is not None and len(resets["x"]) < len(starts):
        raise ValueError(
            f"teacher forcing needs {len(starts)} reset states, got {len(resets['x'])}"
        )
    scale = 1.0 / (steps * observed.shape[1] * 3)
    first = _start_state(rollout, resets, 0)
    rollout.check_laws(first)
    positions = np.empty(tuple(observed.shape))
    positions[0] = first.x.numpy()
    if resets is None and backward:
        return _checkpointed(rollout, observed, starts, segment, scale, positions)
    total = 0.0
    state = first
    for index, start in enumerate(starts):
        if resets is not None:
            state = _start_state(rollout, resets, index)
        with torch.set_grad_enabled(backward):
            loss, state = _segment(rollout, state, observed, start, segment, scale, positions)
            if backward:
                loss.backward()
        total += loss.item()
        state = state.detached()
    return RolloutResult(total, positions)


def _start_state(rollout: Rollout, resets, index: int) -> State:
    if resets is None:
        return State.initial(rollout.scene, rollout.dtype)
    return State.from_arrays(resets, index, rollout.dtype)


def _segment(rollout, state, observed, start, segment, scale, positions):
    """Run one segment from ``state`` at step ``start``: (scaled squared error, end state)."""
    stop = min(start + segment, observed.shape[0] - 1)
    errors = []

    def record(s: int, st: State) -> None:
        step = start + s
        positions[step] = st.x.detach().numpy()
        errors.append(((st.x - observed[step]) ** 2).sum())

    try:
        state = rollout.run(state, stop - start, record)
    except torch.linalg.LinAlgError as error:  # an SVD of NaN: the state is already lost
        step = start + len(errors) + 1
        raise UnstableSimulation(
            f"the simulation became non-finite at step {step} ({str(error).splitlines()[0]})",
            step,
        ) from None
    loss = torch.stack(errors).sum() * scale
    if not torch.isfinite(loss):
        bad = next((start + i + 1 for i, e in enumerate(errors) if not torch.isfinite(e)), stop)
        raise UnstableSimulation(f"the simulation became non-finite at step {bad}", bad)
    return loss, state


def _checkpointed(rollout, observed, starts, segment, scale, positions) -> RolloutResult:
    """No teacher forcing: keep segment starts, then backward last segment first."""
    checkpoints = []
    state = State.initial(rollout.scene, rollout.dtype)
    total = 0.0
    with torch.no_grad():
        for start in starts:
            checkpoints.append(state)
            loss, state = _segment(rollout, state, observed, start, segment, scale, positions)
            total += loss.item()
    carried: tuple[torch.Tensor, ...] | None = None
    for start, checkpoint in zip(reversed(starts), reversed(checkpoints), strict=True):
        leaf = checkpoint.detached(requires_grad=True)
        loss, end = _segment(rollout, leaf, observed, start, segment, scale, positions)
        if carried is not None:
            loss = loss + sum((t * g).sum() for t, g in zip(end.tensors(), carried, strict=True))
        loss.backward()
        carried = tuple(
            torch.zeros_like(t) if t.grad is None else t.grad for t in leaf.tensors()
        )
    return RolloutResult(total, positions)


def _checked(value, law: str, what: str, expected: tuple[int, ...]) -> torch.Tensor:
    if not isinstance(value, torch.Tensor):
        raise LawError(f"the {law} must return a torch.Tensor ({what}), got {type(value).__name__}")
    if tuple(value.shape) != expected:
        raise LawError(
            f"the {law} must return {what} of shape {expected} (B, 3, 3), "
            f"got {tuple(value.shape)}"
        )
    if not torch.isfinite(value).all():
        raise UnstableSimulation(
            f"the {law} returns non-finite {what} (NaN or inf) at the initial state", 0
        )
    return value
