"""Whole MPM steps in one launch, for the forward pass.

The forward pass records everything the reverse pass reads, so it need not run phase by
phase: ``advance`` runs many steps of a small scene in one serial kernel (a Taichi launch
with ndarray arguments costs 15-50 us, more than a 1000-particle phase), and
``step_parallel`` runs one step of a large scene with parallel loops (:func:`step_kernels`).
Both run :func:`mpm_step`, which calls the same Taichi functions as the per-phase kernels
that the reverse pass differentiates. Their arguments are the groups of
:mod:`taichi_mpm.kernels.arguments`: the state, the grid, the records, the material and the
step's constants.
"""

import functools
from collections.abc import Callable
from dataclasses import dataclass

import taichi as ti

from taichi_mpm.kernels import arguments
from taichi_mpm.kernels.arguments import Grid, Records, State
from taichi_mpm.kernels.constitutive import constitutive_update
from taichi_mpm.kernels.transfer import gather, scatter, update_node


@ti.func
def mpm_step(s, state: ti.template(), grid: ti.template(), records: ti.template(),
             material: ti.template(), constants: ti.template()):  # fmt: skip
    """Slot s to s + 1: laws, clear grid slot s, P2G, grid update, G2P.

    The arguments are those of :func:`step_kernels`' kernels (argument packs, read by member:
    Taichi does not bind a pack or an array to a local name). Called at a kernel's top level
    its loops run in parallel; called inside a serial loop they run serially.
    """
    for p in range(state.x.shape[1]):
        constitutive_update(state.F, state.F_corrected, state.stress, records, material, s, p)
    for q in range(grid.mass.shape[1]):
        grid.mass[s, q] = 0.0
        grid.momentum[s, q] = ti.Vector.zero(float, 3)
    for p in range(state.x.shape[1]):
        scatter(state.x, state.v, state.C, state.stress, s, p, grid.mass, grid.momentum,
                constants)  # fmt: skip
    for q in range(grid.mass.shape[1]):
        update_node(grid.mass, grid.momentum, grid.velocity, s, q, constants)
    for p in range(state.x.shape[1]):
        gather(state.x, state.v, state.C, state.F, state.F_corrected, grid.velocity, s, p,
               constants)  # fmt: skip


@dataclass(frozen=True)
class StepKernels:
    """The whole-step kernels for one precision.

    ``advance(state, grid, records, material, constants, first, last)`` advances slots
    first .. last - 1 to first + 1 .. last, serially, in one launch;
    ``step_parallel(state, grid, records, material, constants, s)`` advances slot s with
    parallel loops.
    """

    advance: Callable
    step_parallel: Callable


@functools.cache
def step_kernels(dtype) -> StepKernels:
    """:class:`StepKernels` whose model (material and constants) is in ``dtype``."""
    model = arguments.model_types(dtype)
    Material, Constants = model.material, model.constants

    @ti.kernel
    def advance(state: State, grid: Grid, records: Records, material: Material,
                constants: Constants, first: ti.i32, last: ti.i32):  # fmt: skip
        ti.loop_config(serialize=True)
        for s in range(first, last):
            mpm_step(s, state, grid, records, material, constants)

    @ti.kernel
    def step_parallel(state: State, grid: Grid, records: Records, material: Material,
                      constants: Constants, s: ti.i32):  # fmt: skip
        mpm_step(s, state, grid, records, material, constants)

    return StepKernels(advance, step_parallel)
