"""The kernels' grouped arguments: the model (what a rollout does not change) and the state.

As in ``warp.sim``, a step reads a *model* and advances a *state*. Taichi argument packs
(``ti.types.argpack``, here :class:`PackType`) carry them, so a kernel takes a few named groups
and reads each member by name (``constants.dt``, ``state.x[slot, p]``); adding a constant
touches one definition:

* the model: the scene's :func:`step_constants` (grid, time step, particle mass and volume,
  gravity, walls) and the :func:`material` (the parameter array, the elastic law's kind,
  whether the elastic law reuses the plastic law's SVD, the SVD gradient's tolerance);
* the state: :data:`State`, the particle arrays of a recorded segment, time slot first
  (``x[slot, p]``), :data:`Grid`, one flat row of ``n^3`` nodes per slot, and
  :data:`Records`, the SVD factors and gradient coefficients that the reverse pass reads.

Argument packs, not structs: Taichi 1.7's reverse mode rejects a kernel with a struct argument
("mixed usage of for-loops and statements without looping"), while an argument pack's members
are read where they are used. A pack's scalars are written when the pack is made or a member
is set, not at every launch. A pack type fixes its float type when it is made (a scalar
argument's ``float`` is resolved when the kernel compiles), so the model's pack types, and the
kernels that take them, are made once per precision (:func:`model_types`). Taichi 1.7 also
confuses two pack arguments of one kernel whose arrays share a name (it keys a pack's arrays by
member name alone), so no two pack types here share an array's name (hence :data:`GridGrad`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import taichi as ti

from taichi_mpm import runtime
from taichi_mpm._compat import ArgPack, PackType
from taichi_mpm.scene import WALL_KINDS, Scene

SLIP, STICKY, SEPARATE = 0, 1, 2  # wall_kind; slip is SEPARATE with zero friction
WALL_CODES = {"slip": SLIP, "sticky": STICKY, "separate": SEPARATE}
assert set(WALL_CODES) == set(WALL_KINDS)

#: The particle state that one step carries to the next, in order, with each field's shape per
#: particle: the simulator's checkpoints and ``Simulator.states``, and the bridge's tensors.
CARRIED = {"x": (3,), "v": (3,), "C": (3, 3), "F": (3, 3)}


_array = ti.types.ndarray()

#: Particle arrays: x, v, C and the trial F at slots 0..k, F_corrected and stress at 0..k-1.
State = PackType(x=_array, v=_array, C=_array, F=_array, F_corrected=_array, stress=_array)
#: Grid arrays, one flat row of n^3 nodes per slot (node index: transfer.node_index).
Grid = PackType(mass=_array, momentum=_array, velocity=_array)
#: dL/d of a Grid's arrays (the bridge's reverse step).
GridGrad = PackType(mass_grad=_array, momentum_grad=_array, velocity_grad=_array)
#: What the forward constitutive update records for the per-law reverse kernels: the trial
#: SVD (U, V), the elastic law's own SVD, and each law's gradient coefficients.
Records = PackType(trial_U=_array, trial_V=_array, elastic_U=_array, elastic_V=_array,
                   coeff_von_mises=_array, coeff_sand=_array, coeff_elastic=_array)  # fmt: skip


@dataclass(frozen=True)
class ModelTypes:
    """The model's argument pack types for one float precision."""

    constants: PackType
    material: PackType


@functools.cache
def model_types(dtype) -> ModelTypes:
    """The pack types of :func:`step_constants` and :func:`material` in ``dtype``."""
    return ModelTypes(
        constants=PackType(
            grid_resolution=ti.i32,
            dx=dtype,
            dt=dtype,
            particle_volume=dtype,
            particle_mass=dtype,
            gravity=ti.types.vector(3, dtype),
            wall_kind=ti.i32,
            wall_thickness=ti.i32,
            wall_friction=dtype,
        ),
        material=PackType(
            params=_array, elastic_kind=ti.i32, share_basis=ti.i32, spectral_tol=dtype
        ),
    )


def step_constants(scene: Scene) -> ArgPack:
    """The constants of a step of ``scene``, in the running precision."""
    walls = scene.walls
    return model_types(runtime.current().dtype).constants(
        grid_resolution=scene.grid_resolution,
        dx=scene.dx,
        dt=scene.dt,
        particle_volume=scene.particle_volume,
        particle_mass=scene.particle_mass,
        gravity=scene.gravity,
        wall_kind=WALL_CODES[walls.kind],
        wall_thickness=walls.thickness,
        wall_friction=walls.friction if walls.kind == "separate" else 0.0,
    )


def material(params, elastic_kind: int, share_basis: bool) -> ArgPack:
    """The material's pack: its parameter array (``materials.PARAMETER_NAMES``), the elastic
    law's kind, whether the elastic law reuses the trial SVD, and the SVD gradient's
    tolerance (``RuntimeInfo.spectral_tol``)."""
    info = runtime.current()
    return model_types(info.dtype).material(
        params=params,
        elastic_kind=elastic_kind,
        share_basis=int(share_basis),
        spectral_tol=info.spectral_tol,
    )
