"""MLS-MPM transfer kernels: particle-to-grid, grid update, grid-to-particle.

APIC transfer with quadratic B-splines (Hu et al. 2018). Arrays are time-indexed,
``x[slot, p]``, so no value is overwritten inside a recorded segment and Taichi's
autodiff needs no bookkeeping. The 27-node stencil is unrolled with ``ti.static``:
dynamic stencil loops gave wrong gradients in Taichi 1.7.

A grid slot is one flat row of ``n^3`` nodes, node (i, j, k) at ``(i * n + j) * n + k``
(:func:`node_index`): loops over a grid are then plain 1D loops (a 4D ``ndrange`` divides its
loop index three times per node), and a particle's 27 nodes are one base offset plus
constants.

The step's constants (grid resolution, dx, dt, particle volume and mass, gravity, walls) come
in one argument pack, ``constants`` (:func:`taichi_mpm.kernels.arguments.step_constants`),
read by name; the kernels that take it are made once per precision (:func:`phase_kernels`).
"""

import functools
from collections.abc import Callable
from dataclasses import dataclass

import taichi as ti

from taichi_mpm.kernels import arguments
from taichi_mpm.kernels.arguments import STICKY
from taichi_mpm.kernels.linalg import identity, matmul, matvec, outer, sum_terms

MASS_FLOOR = 1e-12  # grid velocity = momentum / max(mass, floor): no NaN gradients
TANGENT_TINY = 1e-20
STENCIL = [(i, j, k) for i in range(3) for j in range(3) for k in range(3)]  # 27 nodes


@ti.func
def stencil(xp, inv_dx, n):
    """Lower-corner node and quadratic B-spline weights of a particle."""
    Xp = xp * inv_dx
    base = ti.cast(ti.floor(Xp - 0.5), ti.i32)
    base = ti.max(ti.min(base, n - 3), 0)
    fx = Xp - ti.cast(base, float)
    w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1.0) ** 2, 0.5 * (fx - 0.5) ** 2]
    return base, fx, w


@ti.func
def node_index(i, j, k, n):
    """Flat index of node (i, j, k) in a grid row of resolution n."""
    return (i * n + j) * n + k


@ti.func
def node_of(q, n):
    """Node (i, j, k) of flat index q."""
    return ti.Vector([q // (n * n), (q // n) % n, q % n])


@ti.func
def apply_wall(v, d: ti.template(), node, constants: ti.template()):
    """The walls ``constants.wall_thickness`` cells deep on the two faces normal to axis d
    (slip is friction 0): a sticky wall stops a node near it; a slip or separate one takes a
    node's velocity into it away and slows the rest by friction."""
    unit = ti.Vector([1.0 if e == d else 0.0 for e in ti.static(range(3))])
    low = node[d] < constants.wall_thickness
    high = node[d] >= constants.grid_resolution - constants.wall_thickness
    into_wall = ti.cast((low & (v[d] < 0)) | (high & (v[d] > 0)), float)
    near_wall = ti.cast(low | high, float)
    tangent = v - v[d] * unit
    speed = ti.sqrt(tangent.dot(tangent) + TANGENT_TINY)
    slid = tangent * ti.max(0.0, 1.0 - constants.wall_friction * ti.abs(v[d]) / speed)
    sticky = ti.cast(constants.wall_kind == STICKY, float)
    return sticky * (1.0 - near_wall) * v + (1.0 - sticky) * (
        into_wall * slid + (1.0 - into_wall) * v
    )


@ti.func
def apply_walls(v, node, constants: ti.template()):
    """Box walls on every face, axis by axis (:func:`apply_wall`)."""
    for d in ti.static(range(3)):
        v = apply_wall(v, d, node, constants)
    return v


@ti.func
def p2g_particle(xp, vp, Cp, stress_p, grid_mass: ti.template(), grid_momentum: ti.template(),
                 grid_slot, constants: ti.template()):  # fmt: skip
    """One particle's mass, momentum and stress impulse onto its 27 nodes of grid row
    ``grid_slot``, from its position, velocity, affine C and Kirchhoff stress."""
    n, dx, dt = constants.grid_resolution, constants.dx, constants.dt
    particle_mass = constants.particle_mass
    inv_dx = 1.0 / dx
    base, fx, w = stencil(xp, inv_dx, n)
    impulse = (-dt * constants.particle_volume * 4.0 * inv_dx * inv_dx) * stress_p
    affine = impulse + particle_mass * Cp
    momentum = particle_mass * vp
    origin = node_index(base[0], base[1], base[2], n)
    for i, j, k in ti.static(STENCIL):
        dpos = (ti.Vector([i, j, k], dt=float) - fx) * dx
        weight = w[i][0] * w[j][1] * w[k][2]
        q = origin + node_index(i, j, k, n)
        grid_momentum[grid_slot, q] += weight * (momentum + matvec(affine, dpos))
        grid_mass[grid_slot, q] += weight * particle_mass


@ti.func
def scatter(x: ti.template(), v: ti.template(), C: ti.template(), stress: ti.template(), slot, p,
            grid_mass: ti.template(), grid_momentum: ti.template(),
            constants: ti.template()):  # fmt: skip
    """:func:`p2g_particle` of particle p of time slot ``slot`` onto grid slot ``slot``."""
    p2g_particle(x[slot, p], v[slot, p], C[slot, p], stress[slot, p], grid_mass, grid_momentum,
                 slot, constants)  # fmt: skip


@ti.func
def update_node(grid_mass: ti.template(), grid_momentum: ti.template(),
                grid_velocity: ti.template(), grid_slot, q, constants: ti.template()):  # fmt: skip
    """Velocity of node q of grid row ``grid_slot`` from its momentum, plus gravity and the
    walls."""
    mass = grid_mass[grid_slot, q]
    if mass > 0:  # most nodes are empty: skip them (G2P never reads them)
        v = (
            grid_momentum[grid_slot, q] / ti.max(mass, MASS_FLOOR)
            + constants.dt * constants.gravity
        )
        grid_velocity[grid_slot, q] = apply_walls(
            v, node_of(q, constants.grid_resolution), constants
        )
    else:
        grid_velocity[grid_slot, q] = ti.Vector.zero(float, 3)


@ti.func
def g2p_particle(xp, Fc_p, grid_velocity: ti.template(), grid_slot, constants: ti.template()):
    """One particle's next state (x, v, C, F_trial) from grid row ``grid_slot``, its position
    and its deformation gradient after the plastic law."""
    n, dt = constants.grid_resolution, constants.dt
    inv_dx = 1.0 / constants.dx
    base, fx, w = stencil(xp, inv_dx, n)
    origin = node_index(base[0], base[1], base[2], n)
    momenta = [
        w[i][0] * w[j][1] * w[k][2] * grid_velocity[grid_slot, origin + node_index(i, j, k, n)]
        for i, j, k in ti.static(STENCIL)
    ]
    new_v = sum_terms(momenta, 0, 27)
    new_C = (4.0 * inv_dx) * sum_terms(
        [outer(momenta[m], ti.Vector(STENCIL[m], dt=float) - fx) for m in ti.static(range(27))],
        0,
        27,
    )
    return xp + dt * new_v, new_v, new_C, matmul(identity() + dt * new_C, Fc_p)


@ti.func
def gather(x: ti.template(), v: ti.template(), C: ti.template(), F: ti.template(),
           F_corrected: ti.template(), grid_velocity: ti.template(), slot, p,
           constants: ti.template()):  # fmt: skip
    """:func:`g2p_particle` of particle p of time slot ``slot`` from grid slot ``slot``, stored
    at ``slot + 1``."""
    new_x, new_v, new_C, new_F = g2p_particle(x[slot, p], F_corrected[slot, p], grid_velocity,
                                              slot, constants)  # fmt: skip
    v[slot + 1, p] = new_v
    C[slot + 1, p] = new_C
    x[slot + 1, p] = new_x
    F[slot + 1, p] = new_F


@dataclass(frozen=True)
class PhaseKernels:
    """The per-phase kernels for one precision, which the reverse pass differentiates.

    Each takes the arrays it reads and writes, the time slot, the step's ``constants`` and
    ``serial`` (compile-time: serial loops).
    """

    p2g: Callable
    grid_update: Callable
    g2p: Callable


@functools.cache
def phase_kernels(dtype) -> PhaseKernels:
    """:class:`PhaseKernels` whose ``constants`` are in ``dtype``."""
    Constants = arguments.model_types(dtype).constants

    @ti.kernel
    def p2g(x: ti.types.ndarray(), v: ti.types.ndarray(), C: ti.types.ndarray(),
            stress: ti.types.ndarray(), grid_mass: ti.types.ndarray(),
            grid_momentum: ti.types.ndarray(), slot: ti.i32, constants: Constants,
            serial: ti.template()):  # fmt: skip
        """Scatter mass, momentum and the stress impulse of every particle to grid row slot."""
        ti.loop_config(serialize=serial)
        for p in range(x.shape[1]):
            scatter(x, v, C, stress, slot, p, grid_mass, grid_momentum, constants)

    @ti.kernel
    def grid_update(grid_mass: ti.types.ndarray(), grid_momentum: ti.types.ndarray(),
                    grid_velocity: ti.types.ndarray(), slot: ti.i32, constants: Constants,
                    serial: ti.template()):  # fmt: skip
        """Grid velocity from momentum, plus gravity and the box walls."""
        ti.loop_config(serialize=serial)
        for q in range(grid_mass.shape[1]):
            update_node(grid_mass, grid_momentum, grid_velocity, slot, q, constants)

    @ti.kernel
    def g2p(x: ti.types.ndarray(), v: ti.types.ndarray(), C: ti.types.ndarray(),
            F: ti.types.ndarray(), F_corrected: ti.types.ndarray(),
            grid_velocity: ti.types.ndarray(), slot: ti.i32, constants: Constants,
            serial: ti.template()):  # fmt: skip
        """Gather velocity and affine velocity; advect; state of step slot + 1."""
        ti.loop_config(serialize=serial)
        for p in range(x.shape[1]):
            gather(x, v, C, F, F_corrected, grid_velocity, slot, p, constants)

    return PhaseKernels(p2g, grid_update, g2p)
