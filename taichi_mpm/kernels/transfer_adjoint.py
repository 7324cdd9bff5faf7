"""Hand-written reverse of one particle's P2G and G2P (:mod:`taichi_mpm.kernels.transfer`).

Taichi's autodiff of G2P turns each of the 27 grid reads into an atomic scatter of every
intermediate it recomputes, and costs ~4x the forward gather. Written by hand, a particle's
adjoint is one pass over its 27 nodes with a few 3-vectors of accumulators. With quadratic
B-spline weights ``w_n = w(fx_0) w(fx_1) w(fx_2)``, ``fx = x / dx - base``, and node offsets
``o_n = n - fx`` (in cells):

* G2P: ``v' = sum w_n g_n``, ``C' = 4/dx sum w_n g_n o_n^T``, ``x' = x + dt v'`` and
  ``F' = (I + dt C') Fc``. With ``gv = dL/dv' + dt dL/dx'`` and
  ``gC = dL/dC' + dt dL/dF' Fc^T``: ``dL/dg_n = w_n (gv + 4/dx gC o_n)``,
  ``dL/dFc = (I + dt C')^T dL/dF'`` and ``dL/dx = dL/dx' + sum_n (dL/dw_n) dw_n/dx
  - 4/dx^2 gC^T v'``.
* P2G: ``m_n += w_n m``, ``p_n += w_n (m v + A dx o_n)`` with ``A = -dt V 4/dx^2 stress + m C``.
  With ``s = sum w_n dL/dp_n``: ``dL/dv = m s``, ``dL/dA = dx sum w_n dL/dp_n o_n^T``,
  ``dL/dx = sum_n (dL/dw_n) dw_n/dx - A^T s``.
* Grid update of a node with mass ``m > 0``: ``u = p / max(m, floor) + dt g``, then the walls
  along each axis d in turn. A sticky wall zeroes u near it, so passes ``(1 - near) dL/du``.
  A slip or separate wall acts on a node moving into it: with the tangential part
  ``t = u - u_d e_d``, ``s = sqrt(|t|^2 + tiny)`` and ``r = 1 - friction |u_d| / s``, it leaves
  ``t max(r, 0)``, so for ``r > 0`` (else 0) ``dL/du = r h + (h . t) friction
  (|u_d| t / s^3 - sign(u_d) / s e_d)`` with ``h = dL/du'`` off axis d. Then ``dL/dp = dL/du /
  max(m, floor)`` and ``dL/dm = -(dL/du . p) / m^2`` (0 below the floor). An empty node
  passes nothing.

They are checked against Taichi's autodiff of the forward functions (taichi_mpm's reverse
pass) and against finite differences in ``tests/bridges``.
"""

import taichi as ti

from taichi_mpm.kernels.arguments import STICKY
from taichi_mpm.kernels.linalg import identity, matmul_t, matvec, outer, t_matmul, t_matvec
from taichi_mpm.kernels.transfer import (
    MASS_FLOOR,
    STENCIL,
    TANGENT_TINY,
    apply_wall,
    node_index,
    node_of,
    stencil,
)


@ti.func
def _weight_slopes(fx):
    """d w / d fx of the three quadratic B-spline weights, per axis."""
    return [fx - 1.5, 2.0 * (1.0 - fx), fx - 0.5]


@ti.func
def _weight_gradient(w, dw, i: ti.template(), j: ti.template(), k: ti.template()):
    """d w_ijk / d fx for node (i, j, k) of the stencil."""
    return ti.Vector(
        [dw[i][0] * w[j][1] * w[k][2], w[i][0] * dw[j][1] * w[k][2], w[i][0] * w[j][1] * dw[k][2]]
    )


@ti.func
def g2p_particle_adjoint(
    xp, Fc_p, new_v, new_C, grid_velocity: ti.template(), grid_velocity_grad: ti.template(),
    grid_slot, constants: ti.template(), x_out_grad, v_out_grad, C_out_grad, F_out_grad,
):  # fmt: skip
    """Reverse of :func:`~taichi_mpm.kernels.transfer.g2p_particle` (whose results ``new_v``
    and ``new_C`` it takes): adds dL/d(grid velocity) into ``grid_velocity_grad`` and returns
    (dL/dx, dL/dFc) of the particle."""
    n, dt = constants.grid_resolution, constants.dt
    inv_dx = 1.0 / constants.dx
    base, fx, w = stencil(xp, inv_dx, n)
    dw = _weight_slopes(fx)
    origin = node_index(base[0], base[1], base[2], n)
    Fc_grad = t_matmul(identity() + dt * new_C, F_out_grad)
    C_grad = C_out_grad + dt * matmul_t(F_out_grad, Fc_p)
    v_grad = v_out_grad + dt * x_out_grad
    x_grad = x_out_grad - (4.0 * inv_dx * inv_dx) * t_matvec(C_grad, new_v)
    for i, j, k in ti.static(STENCIL):
        q = origin + node_index(i, j, k, n)
        node_grad = v_grad + (4.0 * inv_dx) * matvec(C_grad, ti.Vector([i, j, k], dt=float) - fx)
        weight = w[i][0] * w[j][1] * w[k][2]
        grid_velocity_grad[grid_slot, q] += weight * node_grad
        weight_grad = grid_velocity[grid_slot, q].dot(node_grad)
        x_grad += (inv_dx * weight_grad) * _weight_gradient(w, dw, i, j, k)
    return x_grad, Fc_grad


@ti.func
def p2g_particle_adjoint(xp, vp, Cp, stress_p, grid_mass_grad: ti.template(),
                         grid_momentum_grad: ti.template(), grid_slot,
                         constants: ti.template()):  # fmt: skip
    """Reverse of :func:`~taichi_mpm.kernels.transfer.p2g_particle`: from dL/d(grid mass) and
    dL/d(grid momentum), the particle's (dL/dx, dL/dv, dL/dC, dL/d stress)."""
    n, dx, particle_mass = constants.grid_resolution, constants.dx, constants.particle_mass
    inv_dx = 1.0 / dx
    base, fx, w = stencil(xp, inv_dx, n)
    dw = _weight_slopes(fx)
    stress_scale = -constants.dt * constants.particle_volume * 4.0 * inv_dx * inv_dx
    affine = stress_scale * stress_p + particle_mass * Cp
    momentum = particle_mass * vp
    origin = node_index(base[0], base[1], base[2], n)
    weighted = ti.Vector.zero(float, 3)  # sum of w_n dL/dp_n
    affine_grad = ti.Matrix.zero(float, 3, 3)
    x_grad = ti.Vector.zero(float, 3)
    for i, j, k in ti.static(STENCIL):
        q = origin + node_index(i, j, k, n)
        dpos = (ti.Vector([i, j, k], dt=float) - fx) * dx
        momentum_grad = grid_momentum_grad[grid_slot, q]
        weight = w[i][0] * w[j][1] * w[k][2]
        weight_grad = particle_mass * grid_mass_grad[grid_slot, q] + momentum_grad.dot(
            momentum + matvec(affine, dpos)
        )
        x_grad += (inv_dx * weight_grad) * _weight_gradient(w, dw, i, j, k)
        weighted += weight * momentum_grad
        affine_grad += outer(weight * momentum_grad, dpos)
    x_grad -= t_matvec(affine, weighted)
    return x_grad, particle_mass * weighted, particle_mass * affine_grad, stress_scale * affine_grad


@ti.func
def _wall_adjoint(u, u_grad, d: ti.template(), node, constants: ti.template()):
    """dL/du of one axis' wall step u -> u' (see the module docstring) from dL/du'."""
    friction = constants.wall_friction
    low = node[d] < constants.wall_thickness
    high = node[d] >= constants.grid_resolution - constants.wall_thickness
    grad = u_grad
    if constants.wall_kind == STICKY:
        if low or high:
            grad = ti.Vector.zero(float, 3)
    elif (low and u[d] < 0) or (high and u[d] > 0):
        unit = ti.Vector([1.0 if e == d else 0.0 for e in ti.static(range(3))])
        tangent = u - u[d] * unit
        speed = ti.sqrt(tangent.dot(tangent) + TANGENT_TINY)
        ratio = 1.0 - friction * ti.abs(u[d]) / speed
        grad = ti.Vector.zero(float, 3)
        if ratio > 0:
            off_axis = u_grad - u_grad[d] * unit
            along = off_axis.dot(tangent) * friction
            grad = ratio * off_axis + along * (
                (ti.abs(u[d]) / speed**3) * tangent - (ti.math.sign(u[d]) / speed) * unit
            )
    return grad


@ti.func
def update_node_adjoint(
    grid_mass: ti.template(), grid_momentum: ti.template(), grid_velocity_grad: ti.template(),
    grid_mass_grad: ti.template(), grid_momentum_grad: ti.template(), grid_slot, q,
    constants: ti.template(),
):  # fmt: skip
    """Reverse of :func:`~taichi_mpm.kernels.transfer.update_node`: writes node q's dL/d(mass)
    and dL/d(momentum) from its dL/d(velocity)."""
    mass = grid_mass[grid_slot, q]
    mass_grad = 0.0
    momentum_grad = ti.Vector.zero(float, 3)
    if mass > 0:
        momentum = grid_momentum[grid_slot, q]
        floored = ti.max(mass, MASS_FLOOR)
        node = node_of(q, constants.grid_resolution)
        # the velocity before each axis' walls
        u0 = momentum / floored + constants.dt * constants.gravity
        u1 = apply_wall(u0, 0, node, constants)
        u2 = apply_wall(u1, 1, node, constants)
        grad = grid_velocity_grad[grid_slot, q]
        grad = _wall_adjoint(u2, grad, 2, node, constants)
        grad = _wall_adjoint(u1, grad, 1, node, constants)
        grad = _wall_adjoint(u0, grad, 0, node, constants)
        momentum_grad = grad / floored
        if mass > MASS_FLOOR:
            mass_grad = -grad.dot(momentum) / (mass * mass)
    grid_mass_grad[grid_slot, q] = mass_grad
    grid_momentum_grad[grid_slot, q] = momentum_grad
