"""One MPM step as a ``torch.autograd.Function``.

:func:`mpm_step` takes the particle state and the Kirchhoff stress as torch tensors,

    (x, v, C, F_corrected, stress) -> (x', v', C', F_trial'),

runs P2G, the grid update and G2P in Taichi, and in backward runs their reverse in Taichi
(:mod:`bridges.kernels`). The constitutive laws stay outside, in torch, so a law written as an
``nn.Module`` is differentiated by torch and the simulator by Taichi::

    transfer = Transfer(scene)
    F = plastic(F_trial)             # torch
    stress = elastic(F)              # torch
    x, v, C, F_trial = mpm_step(x, v, C, F, stress, transfer)

Only one step's grid lives in Taichi: backward recomputes the step's grid from the saved
inputs before running the reverse kernels, so the memory of a rollout is that of the
particle tensors torch saves (33 numbers per particle and step) plus the laws' own.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import taichi as ti
import torch

from bridges import kernels
from taichi_mpm import runtime
from taichi_mpm.kernels.arguments import CARRIED, Grid, GridGrad, step_constants
from taichi_mpm.scene import Scene

#: A step's particles from which its CPU loops run in parallel (when Taichi has more than one
#: thread): P2G and the G2P adjoint scatter with atomic adds there. Measured on 2 threads
#: (``benchmarks/bridge_step.py --threads 2 --loops serial parallel``): 10,000 particles took
#: 15.3 ms serial against 18.4 ms parallel, 100,000 took 130 ms against 120 ms.
PARALLEL_MIN_PARTICLES = 32_768


def torch_dtype() -> torch.dtype:
    """The torch dtype matching the running Taichi precision (taichi_mpm.init)."""
    return torch.float64 if runtime.current().dtype == ti.f64 else torch.float32


class Transfer:
    """Taichi arrays and settings for stepping one scene's particles from torch.

    Parameters
    ----------
    scene : taichi_mpm.Scene
        Grid, time step, walls, particle mass and volume (its initial state is not used).
    parallel : bool, optional
        Parallel loops; by default decided before each launch: from ``PARALLEL_MIN_PARTICLES``
        particles (all copies') on a CPU with more than one Taichi thread while other processes
        leave a core for each (:func:`taichi_mpm.runtime.parallel_worthwhile`), always on a GPU.
    batch : int
        Independent copies of the scene stepped at once, each on its own grid: the tensors of a
        step hold ``batch * N`` particles, copy b in rows ``b * N`` to ``(b + 1) * N - 1``.
    """

    def __init__(self, scene: Scene, parallel: bool | None = None, batch: int = 1) -> None:
        if batch < 1:
            raise ValueError(f"batch must be at least 1, got {batch}")
        info = runtime.current()
        self.scene = scene
        self.batch = batch
        self.dtype = torch_dtype()
        self._parallel = parallel
        self._kernels = kernels.step_kernels(info.dtype)
        self._constants = step_constants(scene)
        nodes = scene.grid_resolution**3
        vec = ti.types.vector(3, info.dtype)

        def grid():  # mass, momentum, velocity; copy b: row b, a flat row of n^3 nodes
            return tuple(ti.ndarray(element, shape=(batch, nodes))
                         for element in (info.dtype, vec, vec))  # fmt: skip

        mass, momentum, velocity = grid()
        self.grid = Grid(mass=mass, momentum=momentum, velocity=velocity)
        # dL/d(grid mass, momentum, velocity) of the step being reversed
        mass, momentum, velocity = grid()
        self._grid_grad = GridGrad(mass_grad=mass, momentum_grad=momentum, velocity_grad=velocity)
        # each copy's occupied box of grid nodes, measured by every launch (bridges.kernels)
        self._box = ti.ndarray(ti.i32, shape=(batch, 6))

    @property
    def num_particles(self) -> int:
        """Particles of one step: all copies'."""
        return self.batch * self.scene.num_particles

    @property
    def _serial(self) -> bool:
        """Whether the next launch loops serially (asked anew each launch by default)."""
        if self._parallel is not None:
            return not self._parallel
        return not runtime.parallel_worthwhile(self.num_particles, PARALLEL_MIN_PARTICLES)

    def forward(self, packed: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The next state from a packed (B * N, 33) input: its (B * N, 15) motion (x, v, C)
        and its (B * N, 9) F_trial."""
        motion = packed.new_empty(packed.shape[0], kernels.MOTION_WIDTH)
        trial_F = packed.new_empty(packed.shape[0], 9)
        self._kernels.forward(packed, motion, trial_F, self.grid, self._box, self._constants,
                              self._serial)  # fmt: skip
        return motion, trial_F

    def backward(self, packed: torch.Tensor, motion: torch.Tensor,
                 output_grad: torch.Tensor) -> torch.Tensor:  # fmt: skip
        """Packed (B * N, 33) dL/d(input) of one step from its packed (B * N, 33) input, the
        (B * N, 15) motion it output and the packed (B * N, 24) dL/d(x, v, C, F_trial)."""
        input_grad = packed.new_empty(packed.shape)
        self._kernels.backward(packed, motion, output_grad.contiguous(), input_grad, self.grid,
                               self._grid_grad, self._box, self._constants,
                               self._serial)  # fmt: skip
        return input_grad


def _flat(tensor: torch.Tensor, name: str, shape: tuple[int, ...], dtype) -> torch.Tensor:
    if tuple(tensor.shape) != shape:
        raise ValueError(f"{name} must have shape {shape}, got {tuple(tensor.shape)}")
    if tensor.dtype != dtype:
        raise TypeError(
            f"{name} is {tensor.dtype} but the simulation runs in {dtype} "
            "(taichi_mpm.init precision): convert the law's parameters with .to(dtype)"
        )
    return tensor.detach().reshape(shape[0], -1)


def _unpack(packed: torch.Tensor, shapes: Iterable[tuple[int, ...]]) -> tuple[torch.Tensor, ...]:
    """Views of packed rows, one (N, *shape) per field."""
    views, start = [], 0
    for shape in shapes:
        width = math.prod(shape)
        part = packed[:, start : start + width]
        views.append(part if len(shape) == 1 else part.unflatten(1, shape))
        start += width
    return tuple(views)


@dataclass(frozen=True)
class StressRecipe:
    """How a stress can be computed again from tensors the graph keeps anyway:
    ``compute(*tensors)`` gives it, (N, 3, 3), without a graph. A law whose reverse keeps such
    tensors attaches one to the stress it returns (:func:`attach_recipe`); a step then keeps
    them, not the stress, and computes the stress again in its reverse (which needs it to
    redo the step's grid)."""

    tensors: tuple[torch.Tensor, ...]
    compute: Callable[..., torch.Tensor]


_RECIPE_ATTRIBUTE = "_sga_stress_recipe"


def attach_recipe(stress: torch.Tensor, recipe: StressRecipe) -> torch.Tensor:
    """``stress``, carrying ``recipe`` (see :class:`StressRecipe`)."""
    setattr(stress, _RECIPE_ATTRIBUTE, recipe)
    return stress


def recipe_of(stress: torch.Tensor) -> StressRecipe | None:
    """The :class:`StressRecipe` ``stress`` carries, if any."""
    return getattr(stress, _RECIPE_ATTRIBUTE, None)


class _MPMStep(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x, v, C, F, stress, transfer: Transfer):
        ctx.transfer = transfer
        # the inputs, not their packed copy: x, v and C are views of the previous step's
        # output, which the graph keeps anyway, so only F and stress cost memory; a stress
        # that can be computed again from what its law keeps is not kept
        recipe = recipe_of(stress)
        ctx.recompute = None if recipe is None else recipe.compute
        ctx.save_for_backward(x, v, C, F, *((stress,) if recipe is None else recipe.tensors))
        # the output's motion: the next step's x, v and C are views of it, so it costs no
        # memory (a plain tensor without a graph: holding it makes no reference cycle); the
        # trial F is a tensor of its own, freed once the plastic law has read it (unless the
        # law keeps it)
        ctx.motion, trial_F = transfer.forward(_packed(transfer, x, v, C, F, stress))
        motion = _unpack(ctx.motion, [CARRIED[name] for name in kernels.MOTION_FIELDS])
        return (*motion, trial_F.unflatten(1, CARRIED["F"]))

    @staticmethod
    def backward(ctx, *output_grads):
        x, v, C, F, *kept = ctx.saved_tensors
        stress = kept[0] if ctx.recompute is None else ctx.recompute(*kept)
        packed = _packed(ctx.transfer, x, v, C, F, stress)
        N = packed.shape[0]
        widths = [math.prod(shape) for shape in CARRIED.values()]
        output_grad = torch.cat(
            [
                packed.new_zeros(N, w) if g is None else g.reshape(N, w)
                for g, w in zip(output_grads, widths, strict=True)
            ],
            dim=1,
        )
        input_grad = ctx.transfer.backward(packed, ctx.motion, output_grad)
        return (*_unpack(input_grad, kernels.INPUT_FIELDS.values()), None)


def _packed(transfer: Transfer, *tensors: torch.Tensor) -> torch.Tensor:
    """One (N, 33) row per particle from x, v, C, F, stress (checked shapes and dtype)."""
    N, dtype = transfer.num_particles, transfer.dtype
    fields = kernels.INPUT_FIELDS.items()
    return torch.cat(
        [
            _flat(tensor, name, (N, *shape), dtype)
            for tensor, (name, shape) in zip(tensors, fields, strict=True)
        ],
        dim=1,
    )


def mpm_step(x, v, C, F, stress, transfer: Transfer):
    """One differentiable MPM step; see the module docstring.

    Parameters
    ----------
    x : (N, 3) tensor
        Positions.
    v : (N, 3) tensor
        Velocities.
    C : (N, 3, 3) tensor
        APIC affine velocity.
    F : (N, 3, 3) tensor
        Deformation gradient after the plastic law (F_corrected).
    stress : (N, 3, 3) tensor
        Kirchhoff stress from the elastic law.
    transfer : Transfer
        The scene's Taichi arrays.

    Returns
    -------
    x, v, C, F_trial of the next step.
    """
    dtype = transfer.dtype
    return _MPMStep.apply(*(t.to(dtype) for t in (x, v, C, F, stress)), transfer)
