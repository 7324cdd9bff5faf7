"""Trajectories of torch constitutive laws through the Taichi MPM, with segment-wise backward.

A step applies the plastic law (F_trial -> F), the elastic law (F -> Kirchhoff stress) and
:func:`bridges.step.mpm_step`. :func:`trajectory_loss` compares a simulated trajectory with an
observed one and back-propagates the mean squared position error into the laws' parameters one
segment at a time, so memory holds one segment's graph, never the whole trajectory:

* with ``resets`` (teacher forcing), each segment starts from the observed state, so the
  segments are independent: ``batch`` of them at a time run as one batch of independent copies
  of the scene (each on its own grid, see :class:`bridges.step.Transfer`), so a 1000-step
  epoch of 100-step segments takes 100 steps of ten copies instead of 1000 steps of one;
* without, the state at each segment start is kept, and the backward pass re-runs the
  segments last to first, carrying dL/d(state) across their boundaries (checkpointing).

Laws run inside :func:`bridges.linalg.stable_linalg`, so ``torch.linalg.svd`` in a law gets
gradients that stay finite for repeated singular values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn
from torch.autograd.function import once_differentiable

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

    @classmethod
    def stacked(cls, states: list[State]) -> State:
        """The states of several copies of a scene as one batch, copy after copy."""
        columns = zip(*(state.tensors() for state in states), strict=True)
        return cls(*(torch.cat(parts) for parts in columns))

    def tensors(self) -> tuple[torch.Tensor, ...]:
        return (self.x, self.v, self.C, self.F)

    def detached(self, requires_grad: bool = False) -> State:
        return State(*(t.detach().clone().requires_grad_(requires_grad) for t in self.tensors()))


@dataclass
class RolloutResult:
    """Mean squared position error and the simulated positions: (steps + 1, N, 3) against a
    dense trajectory, (frames, P, 3) at the frames and particles of :class:`Frames`."""

    loss: float
    positions: np.ndarray


@dataclass(frozen=True)
class Frames:
    """Positions observed at some steps, of some particles: what a simulation is compared with
    when not every step and particle was seen (video frames, tracked points). It holds only
    what was observed, so its memory does not grow with the steps between frames.

    ``steps`` (frames,): increasing step indices, each at least 1; ``positions``
    (frames, P, 3); ``particles`` (P,): which of the scene's particles were observed, None for
    all of them in order.
    """

    steps: np.ndarray
    positions: torch.Tensor | np.ndarray
    particles: np.ndarray | None = None

    def __post_init__(self) -> None:
        steps = np.asarray(self.steps, dtype=np.int64)
        if steps.ndim != 1 or len(steps) == 0 or steps[0] < 1 or (np.diff(steps) <= 0).any():
            raise ValueError("Frames.steps must be increasing step indices, each at least 1")
        if tuple(self.positions.shape[:1]) != (len(steps),) or self.positions.shape[-1] != 3:
            raise ValueError(f"Frames.positions must have shape ({len(steps)}, P, 3), got "
                             f"{tuple(self.positions.shape)}")  # fmt: skip
        object.__setattr__(self, "steps", steps)

    @property
    def last_step(self) -> int:
        return int(self.steps[-1])


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
        self._batched: dict[int, Transfer] = {1: self.transfer}

    def transfer_for(self, batch: int) -> Transfer:
        """The Taichi arrays for ``batch`` copies of the scene (made once per batch size)."""
        if batch not in self._batched:
            self._batched[batch] = Transfer(self.scene, batch=batch)
        return self._batched[batch]

    def step(self, state: State, batch: int = 1) -> State:
        """One differentiable step of ``batch`` independent copies (their states stacked)."""
        F = self.plastic(state.F)
        stress = self.elastic(F)
        return State(*mpm_step(state.x, state.v, state.C, F, stress, self.transfer_for(batch)))

    def check_laws(self, state: State) -> None:
        """Check that both laws map ``state.F`` to finite (N, 3, 3) tensors, particle by
        particle.

        Raises :class:`LawError` for a wrong type or shape or a law that mixes particles,
        :class:`UnstableSimulation` for NaN or inf.
        """
        expected = tuple(state.F.shape)
        with torch.no_grad(), stable_linalg():
            F = _checked(self.plastic(state.F), "plastic law", "F_corrected", expected)
            _checked(self.elastic(F), "elastic law", "Kirchhoff stress", expected)
            _check_per_particle(self.plastic, state.F, "plastic law")
            _check_per_particle(self.elastic, F, "elastic law")

    def run(self, state: State, steps: int, on_step=None, batch: int = 1) -> State:
        """``steps`` steps from ``state``; ``on_step(step_index, state)`` after each."""
        with stable_linalg():
            for s in range(steps):
                state = self.step(state, batch)
                if on_step is not None:
                    on_step(s + 1, state)
        return state

    def simulate(
        self, state: State | None = None, steps: int | None = None, kept: np.ndarray | None = None
    ) -> np.ndarray:
        """Positions of every step, (steps + 1, N, 3), without gradients; with ``kept`` (step
        indices, increasing), of those steps only, (len(kept), N, 3)."""
        state = state or State.initial(self.scene, self.dtype)
        steps = self.scene.steps if steps is None else steps
        wanted = None if kept is None else {int(step) for step in kept}
        if wanted is not None and (
            len(wanted) != len(kept) or not all(0 <= step <= steps for step in wanted)
        ):
            raise ValueError(f"kept steps must lie in [0, {steps}] and be distinct")
        positions = [state.x.numpy().copy()] if wanted is None or 0 in wanted else []

        def record(step: int, now: State) -> None:
            if wanted is None or step in wanted:
                positions.append(now.x.numpy().copy())

        with torch.no_grad():
            self.run(state, steps, record)
        return np.stack(positions)


def trajectory_loss(
    rollout: Rollout,
    observed: torch.Tensor | np.ndarray | Frames,
    resets: dict[str, np.ndarray] | None = None,
    segment: int = 100,
    backward: bool = True,
    batch: int = 1,
) -> RolloutResult:
    """Mean squared position error against ``observed``, differentiated segment by segment.

    Parameters
    ----------
    rollout : Rollout
        Scene and laws; the gradients accumulate in the laws' parameters' ``.grad``.
    observed : (steps + 1, N, 3) or Frames
        Observed positions at every step, from step 0; or a :class:`Frames` of the steps and
        particles that were observed (the simulation then runs to its last step, and neither
        the observation nor the result holds the steps between frames).
    resets : dict of stacked states, optional
        Teacher forcing: entry i (keys x, v, C, F) is the observed state at step
        ``i * segment``; each segment then starts from it. Without, segment 0 starts from the
        scene's initial state and each later one from where the previous one ended.
    segment : int
        Steps per segment.
    backward : bool
        Back-propagate (otherwise only the loss and positions).
    batch : int
        With teacher forcing, segments of equal length run this many at a time, as one batch
        of copies of the scene. The result is the same (to round-off) for every batch size;
        memory grows with it (the graph of ``batch`` segments is held at once).

    Raises
    ------
    LawError, UnstableSimulation
        A law returned a wrong shape, or the loss became non-finite.
    """
    if isinstance(observed, Frames):
        if resets is not None:
            raise ValueError("Frames are compared without teacher forcing")
        compare: _Comparison = _SparseComparison(observed, rollout)
    else:
        compare = _DenseComparison(observed, rollout.dtype)
    steps = compare.steps
    if steps < 1 or segment < 1 or batch < 1:
        raise ValueError("observed needs at least two frames; segment and batch must be >= 1")
    starts = list(range(0, steps, segment))
    if resets is not None and len(resets["x"]) < len(starts):
        raise ValueError(
            f"teacher forcing needs {len(starts)} reset states, got {len(resets['x'])}"
        )
    first = _start_state(rollout, resets, 0)
    rollout.check_laws(first)
    compare.start(first)
    if resets is None and backward:
        return _checkpointed(rollout, compare, starts, segment)
    total = 0.0
    if resets is None:  # forward only: one segment after the other
        groups = [[index] for index in range(len(starts))]
    else:
        groups = _groups(starts, steps, segment, batch)
    state = first
    for group in groups:
        if resets is not None:
            state = State.stacked([_start_state(rollout, resets, index) for index in group])
        with torch.set_grad_enabled(backward):
            group_starts = [starts[index] for index in group]
            loss, state = _segment(rollout, state, compare, group_starts, segment)
            if backward:
                loss.backward()
        total += loss.item()
        state = state.detached()
        del loss  # the group's graph: its steps' outputs are freed before the next group runs
    return RolloutResult(total, compare.positions)


def step_graph_bytes(rollout: Rollout, state: State) -> int:
    """Bytes of autograd graph one differentiable step of ``state`` keeps (all its copies).

    Measured, not guessed: a step is run with gradients from the end of another one and what
    its graph keeps is counted (the tensors it saves, the laws' intermediates and the packed
    input among them, and the storage of its input state). The step's input requires a
    gradient, as inside a segment: otherwise autograd would keep nothing for the laws'
    operations before their first parameter (an SVD of the input, say), and the count would
    fall short.
    """
    with torch.no_grad():
        previous = rollout.step(state.detached())  # its outputs are views of one packed tensor
    previous = State(*(tensor.requires_grad_() for tensor in previous.tensors()))
    storage = previous.F.untyped_storage()
    kept: dict[int, int] = {storage.data_ptr(): storage.nbytes()}

    def count(tensor: torch.Tensor) -> torch.Tensor:
        storage = tensor.untyped_storage()
        kept[storage.data_ptr()] = storage.nbytes()
        return tensor

    with torch.autograd.graph.saved_tensors_hooks(count, lambda tensor: tensor), stable_linalg():
        rollout.step(previous)  # a step's loss term keeps nothing of its own (_SquaredError)
    return sum(kept.values())


def segments_per_batch(rollout: Rollout, state: State, segment: int, budget_bytes: int) -> int:
    """How many teacher-forced segments of ``segment`` steps fit ``budget_bytes`` of graph: a
    segment holds ``segment`` steps of :func:`step_graph_bytes` per copy. At least 1."""
    return max(1, budget_bytes // max(1, step_graph_bytes(rollout, state) * segment))


class GraphBudgetError(MemoryError):
    """Even the best segment length of a checkpointed gradient needs more than the budget."""


def checkpoint_segment(
    rollout: Rollout, steps: int, budget_bytes: int, longest: int, slack: float = 1.0
) -> tuple[int, int]:
    """The segment length a checkpointed gradient over ``steps`` steps runs with, at most
    ``longest``, and the bytes it needs: one segment's graph (its steps of
    :func:`step_graph_bytes`, measured on the rollout's laws at the scene's initial state)
    plus the state kept at every segment's start, times ``slack``, what the process's memory
    grows by per byte so counted (the C allocator does not reuse every hole a step's
    temporaries leave between the tensors the graph keeps). The longest segment within
    ``budget_bytes``; a length needs less the closer it is to sqrt(steps * state / step).

    Raises :class:`GraphBudgetError` when no length fits, naming what it needs.
    """
    state = State.initial(rollout.scene, rollout.dtype)
    per_step = step_graph_bytes(rollout, state)
    per_state = sum(tensor.nbytes for tensor in state.tensors())

    def needed(length: int) -> int:
        return math.ceil(slack * (length * per_step + math.ceil(steps / length) * per_state))

    fitting = [length for length in range(1, min(longest, steps) + 1)
               if needed(length) <= budget_bytes]  # fmt: skip
    if not fitting:
        least = min(range(1, steps + 1), key=needed)
        raise GraphBudgetError(
            f"the gradient over {steps} steps of {rollout.scene.num_particles} particles needs "
            f"{needed(least) / 2**20:.3g} MiB at least (segments of {least} steps; its graph "
            f"{per_step / 2**20:.3g} MiB a step with this law, {slack:g}x for the allocator), "
            f"more than the budget of {budget_bytes / 2**20:.3g} MiB"
        )
    length = max(fitting)
    return length, needed(length)


def _groups(starts: list[int], steps: int, segment: int, batch: int) -> list[list[int]]:
    """Segment indices in as few runs of at most ``batch`` full segments as there can be, the
    runs as even as they can be (10 segments at 6 a batch: 5 and 5, so the graph held at once is
    5 segments', at the speed of 2 runs); a short last segment alone."""
    full = [index for index, start in enumerate(starts) if start + segment <= steps]
    runs = math.ceil(len(full) / batch)
    size = math.ceil(len(full) / runs) if runs else 1
    groups = [full[i : i + size] for i in range(0, len(full), size)]
    return groups + [[index] for index in range(len(full), len(starts))]


def _start_state(rollout: Rollout, resets, index: int) -> State:
    if resets is None:
        return State.initial(rollout.scene, rollout.dtype)
    return State.from_arrays(resets, index, rollout.dtype)


class _Comparison:
    """How a segment's steps are compared with the observation and what of them is kept."""

    steps: int  # the last step simulated
    scale: float  # of the summed squared errors: 1 / (3 x the observed positions)
    positions: np.ndarray  # what the result reports as simulated

    def start(self, state: State) -> None:
        """Record the initial ``state``."""

    def error(self, offset: int, state: State, starts: list[int]) -> torch.Tensor | None:
        """The squared error of ``state`` (copies stacked, the copy of start ``starts[i]``
        at step ``starts[i] + offset``), None when none of its steps was observed; records
        what the result keeps."""
        raise NotImplementedError

    def first_non_finite(self, starts: list[int], length: int) -> int:
        """The earliest non-finite step of the given segments (or the last of them)."""
        raise NotImplementedError


class _DenseComparison(_Comparison):
    """Every particle observed at every step after the first; every step's positions kept."""

    def __init__(self, observed, dtype: torch.dtype) -> None:
        self.observed = torch.as_tensor(observed, dtype=dtype)
        self.steps = self.observed.shape[0] - 1
        self.scale = 1.0 / (self.steps * self.observed.shape[1] * 3)
        self.positions = np.empty(tuple(self.observed.shape), dtype=self.observed.numpy().dtype)

    def start(self, state: State) -> None:
        self.positions[0] = state.x.numpy()

    def error(self, offset: int, state: State, starts: list[int]) -> torch.Tensor:
        N = self.observed.shape[1]
        x = state.x.detach().numpy().reshape(len(starts), N, 3)
        for copy, start in enumerate(starts):
            self.positions[start + offset] = x[copy]
        rows = torch.as_tensor(starts) + offset
        return _SquaredError.apply(state.x, self.observed, rows)

    def first_non_finite(self, starts: list[int], length: int) -> int:
        bad = [
            start + offset
            for start in starts
            for offset in range(1, length + 1)
            if not np.isfinite(self.positions[start + offset]).all()
        ]
        return min(bad, default=starts[0] + length)


class _SparseComparison(_Comparison):
    """The steps and particles of :class:`Frames` observed; their simulated positions kept."""

    def __init__(self, frames: Frames, rollout: Rollout) -> None:
        dtype, N = rollout.dtype, rollout.scene.num_particles
        self.steps = frames.last_step
        self.rows = {int(step): row for row, step in enumerate(frames.steps)}
        self.observed = torch.as_tensor(frames.positions, dtype=dtype)
        particles = np.arange(N) if frames.particles is None else np.asarray(frames.particles)
        if (
            self.observed.shape[1] != len(particles)
            or particles.min(initial=0) < 0
            or (particles.max(initial=0) >= N)
        ):
            raise ValueError(f"Frames.particles must index the scene's {N} particles, one per "
                             "observed column")  # fmt: skip
        self.particles = None if frames.particles is None else torch.as_tensor(particles)
        self.scale = 1.0 / (self.observed.shape[0] * self.observed.shape[1] * 3)
        self.positions = np.empty(tuple(self.observed.shape), dtype=self.observed.numpy().dtype)
        self.non_finite: int | None = None  # the first step whose positions are not finite

    def error(self, offset: int, state: State, starts: list[int]) -> torch.Tensor | None:
        step = starts[0] + offset
        if self.non_finite is None and not torch.isfinite(state.x).all():
            self.non_finite = step
        row = self.rows.get(step)
        if row is None:
            return None
        x = state.x if self.particles is None else state.x[self.particles]
        self.positions[row] = x.detach().numpy()
        return _SquaredError.apply(x, self.observed, torch.tensor([row]))

    def first_non_finite(self, starts: list[int], length: int) -> int:
        return starts[0] + length if self.non_finite is None else self.non_finite


def _segment(rollout, state, compare: _Comparison, starts, segment):
    """Run the segments from ``starts`` (a batch of copies, states stacked in ``state``):
    (their scaled squared error, the stacked end state)."""
    stop = min(starts[0] + segment, compare.steps)
    length = stop - starts[0]
    errors = []
    ran = 0

    def record(s: int, st: State) -> None:
        nonlocal ran
        ran = s
        error = compare.error(s, st, starts)
        if error is not None:
            errors.append(error)

    try:
        state = rollout.run(state, length, record, batch=len(starts))
    except torch.linalg.LinAlgError as error:  # an SVD of NaN: the state is already lost
        step = starts[0] + ran + 1
        raise UnstableSimulation(
            f"the simulation became non-finite at step {step} ({str(error).splitlines()[0]})",
            step,
        ) from None
    # no observed step in the segment (Frames): the end state alone carries the gradient
    loss = torch.stack(errors).sum() * compare.scale if errors else state.x.sum() * 0.0
    if not torch.isfinite(loss):
        bad = compare.first_non_finite(starts, length)
        raise UnstableSimulation(f"the simulation became non-finite at step {bad}", bad)
    return loss, state


class _SquaredError(torch.autograd.Function):
    """The squared error of a step's stacked positions ``x`` against the observed frames
    ``rows`` (one per copy), keeping only references for the reverse: ``x`` is part of the
    step's output, which the graph holds anyway, and the observed positions are the whole
    trajectory's, so a step's error costs the graph no memory of its own."""

    @staticmethod
    def forward(ctx, x, observed, rows):
        ctx.save_for_backward(x, observed, rows)
        difference = x - observed[rows].reshape(x.shape)
        return (difference * difference).sum()

    @staticmethod
    @once_differentiable
    def backward(ctx, grad):
        x, observed, rows = ctx.saved_tensors
        difference = x - observed[rows].reshape(x.shape)
        return 2 * grad * difference, None, None


def _checkpointed(rollout, compare: _Comparison, starts, segment) -> RolloutResult:
    """No teacher forcing: keep segment starts, then backward last segment first."""
    checkpoints = []
    state = State.initial(rollout.scene, rollout.dtype)
    total = 0.0
    with torch.no_grad():
        for start in starts:
            checkpoints.append(state)
            loss, state = _segment(rollout, state, compare, [start], segment)
            total += loss.item()
    carried: tuple[torch.Tensor, ...] | None = None
    for start, checkpoint in zip(reversed(starts), reversed(checkpoints), strict=True):
        leaf = checkpoint.detached(requires_grad=True)
        loss, end = _segment(rollout, leaf, compare, [start], segment)
        if carried is not None:
            loss = loss + sum((t * g).sum() for t, g in zip(end.tensors(), carried, strict=True))
        loss.backward()
        carried = tuple(torch.zeros_like(t) if t.grad is None else t.grad for t in leaf.tensors())
        del loss, end  # this segment's graph, before the one before it runs
    return RolloutResult(total, compare.positions)


def _check_per_particle(law: nn.Module, F: torch.Tensor, name: str) -> None:
    """A constitutive law maps each particle's F alone: on F made distinct per particle (a
    fixed 1 % perturbation), the law on the two halves of the batch, and on the batch reversed,
    must give the same rows (the batched segments rely on it)."""
    half = F.shape[0] // 2
    if half < 1:
        return
    noise = torch.randn(F.shape, generator=torch.Generator().manual_seed(0), dtype=F.dtype)
    F = F + 0.01 * noise
    whole = law(F)
    split = torch.cat([law(F[:half]), law(F[half:])])
    reversed_rows = law(F.flip(0)).flip(0)
    tolerance = 1e-5 * float(whole.abs().max()) + 1e-30
    for other in (split, reversed_rows):
        if not torch.allclose(other, whole, rtol=1e-5, atol=tolerance, equal_nan=True):
            raise LawError(
                f"the {name} mixes particles: its result for one particle depends on the "
                "others (a sum, mean or other reduction over the first dimension, or an "
                "ordering by particle); a constitutive law maps each particle's F on its "
                "own, so reduce only over the last dimensions (dim=-1 or (-2, -1))"
            )


def _checked(value, law: str, what: str, expected: tuple[int, ...]) -> torch.Tensor:
    if not isinstance(value, torch.Tensor):
        raise LawError(f"the {law} must return a torch.Tensor ({what}), got {type(value).__name__}")
    if tuple(value.shape) != expected:
        raise LawError(
            f"the {law} must return {what} of shape {expected} (B, 3, 3), got {tuple(value.shape)}"
        )
    if not torch.isfinite(value).all():
        raise UnstableSimulation(
            f"the {law} returns non-finite {what} (NaN or inf) at the initial state", 0
        )
    return value
