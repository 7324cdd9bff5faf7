"""P2G and G2P of one particle with stencil loops, and their hand-written reverse.

Taichi's autodiff needs the 27-node stencil unrolled (:mod:`taichi_mpm.kernels.transfer`), and
an unrolled stencil costs its Python front end ~1 s per kernel each time a process first
launches it, even with the offline cache (Taichi 1.7.4, measured: 0.9 s unrolled against
0.15 s looped). Kernels that Taichi does not differentiate (the bridge's step and its
hand-written reverse) use these looped versions instead; they compute the same values
(tested against the unrolled ones and Taichi's autodiff of them in ``tests/bridges``).

Taichi's autodiff of G2P turns each of the 27 grid reads into an atomic scatter of every
intermediate it recomputes; written by hand, a particle's adjoint is one pass over its nodes
with a few accumulators. With quadratic B-spline weights ``w_n = w(fx_0) w(fx_1) w(fx_2)``,
``fx = x / dx - base``, and node offsets ``o_n = n - fx`` (in cells):

* G2P: ``v' = sum w_n g_n``, ``C' = 4/dx sum w_n g_n o_n^T``, ``x' = x + dt v'`` and
  ``F' = (I + dt C') Fc``. With ``gv = dL/dv' + dt dL/dx'`` and
  ``gC = dL/dC' + dt dL/dF' Fc^T``: ``dL/dg_n = w_n (gv + 4/dx gC o_n)``,
  ``dL/dFc = (I + dt C')^T dL/dF'`` and ``dL/dx = dL/dx' + sum_n (dL/dw_n) dw_n/dx
  - 4/dx^2 gC^T v'``.
* P2G: ``m_n += w_n m``, ``p_n += w_n (m v + A dx o_n)`` with ``A = -dt V 4/dx^2 stress + m C``.
  With ``s = sum w_n dL/dp_n``: ``dL/dv = m s``, ``dL/dA = dx sum w_n dL/dp_n o_n^T``,
  ``dL/dx = sum_n (dL/dw_n) dw_n/dx - A^T s``.
"""

import taichi as ti

from taichi_mpm.kernels.linalg import identity, matmul, matmul_t, matvec, outer, t_matmul, t_matvec
from taichi_mpm.kernels.transfer import STENCIL, node_index


@ti.func
def stencil_rows(xp, inv_dx, n):
    """Lower-corner node, fx, and the quadratic B-spline weights and their slopes d w / d fx
    as 3x3 matrices (row: the node's offset 0, 1, 2; column: the axis)."""
    Xp = xp * inv_dx
    base = ti.max(ti.min(ti.cast(ti.floor(Xp - 0.5), ti.i32), n - 3), 0)
    fx = Xp - ti.cast(base, float)
    w = ti.Matrix.rows([0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1.0) ** 2, 0.5 * (fx - 0.5) ** 2])
    dw = ti.Matrix.rows([fx - 1.5, 2.0 * (1.0 - fx), fx - 0.5])
    return base, fx, w, dw


@ti.func
def _weight_gradient(w, dw, i, j, k):
    """d w_ijk / d fx."""
    return ti.Vector(
        [dw[i, 0] * w[j, 1] * w[k, 2], w[i, 0] * dw[j, 1] * w[k, 2], w[i, 0] * w[j, 1] * dw[k, 2]]
    )


@ti.func
def p2g_particle(
    xp, vp, Cp, stress_p, grid_mass: ti.template(), grid_momentum: ti.template(), grid_slot, n,
    dx, dt, particle_volume, particle_mass,
):  # fmt: skip
    """:func:`taichi_mpm.kernels.transfer.p2g_particle` with a stencil loop."""
    inv_dx = 1.0 / dx
    base, fx, w, _ = stencil_rows(xp, inv_dx, n)
    affine = (-dt * particle_volume * 4.0 * inv_dx * inv_dx) * stress_p + particle_mass * Cp
    momentum = particle_mass * vp
    origin = node_index(base[0], base[1], base[2], n)
    for i, j, k in ti.static(STENCIL):
        weight = w[i, 0] * w[j, 1] * w[k, 2]
        q = origin + node_index(i, j, k, n)
        dpos = (ti.Vector([i, j, k], dt=float) - fx) * dx
        grid_momentum[grid_slot, q] += weight * (momentum + matvec(affine, dpos))
        grid_mass[grid_slot, q] += weight * particle_mass


@ti.func
def g2p_particle(xp, Fc_p, grid_velocity: ti.template(), grid_slot, n, dx, dt):
    """:func:`taichi_mpm.kernels.transfer.g2p_particle` with a stencil loop."""
    inv_dx = 1.0 / dx
    base, fx, w, _ = stencil_rows(xp, inv_dx, n)
    origin = node_index(base[0], base[1], base[2], n)
    new_v = ti.Vector.zero(float, 3)
    new_C = ti.Matrix.zero(float, 3, 3)
    for i, j, k in ti.static(STENCIL):
        momentum = (
            w[i, 0] * w[j, 1] * w[k, 2] * grid_velocity[grid_slot, origin + node_index(i, j, k, n)]
        )
        new_v += momentum
        new_C += outer(momentum, ti.Vector([i, j, k], dt=float) - fx)
    new_C *= 4.0 * inv_dx
    return xp + dt * new_v, new_v, new_C, matmul(identity() + dt * new_C, Fc_p)


@ti.func
def g2p_particle_adjoint(
    xp, Fc_p, new_v, new_C, grid_velocity: ti.template(), grid_velocity_grad: ti.template(),
    grid_slot, n, dx, dt, x_out_grad, v_out_grad, C_out_grad, F_out_grad,
):  # fmt: skip
    """Reverse of :func:`g2p_particle` (whose results ``new_v`` and ``new_C`` it takes): adds
    dL/d(grid velocity) into ``grid_velocity_grad`` and returns (dL/dx, dL/dFc)."""
    inv_dx = 1.0 / dx
    base, fx, w, dw = stencil_rows(xp, inv_dx, n)
    origin = node_index(base[0], base[1], base[2], n)
    Fc_grad = t_matmul(identity() + dt * new_C, F_out_grad)
    C_grad = C_out_grad + dt * matmul_t(F_out_grad, Fc_p)
    v_grad = v_out_grad + dt * x_out_grad
    x_grad = x_out_grad - (4.0 * inv_dx * inv_dx) * t_matvec(C_grad, new_v)
    for i, j, k in ti.static(STENCIL):
        q = origin + node_index(i, j, k, n)
        node_grad = v_grad + (4.0 * inv_dx) * matvec(C_grad, ti.Vector([i, j, k], dt=float) - fx)
        grid_velocity_grad[grid_slot, q] += w[i, 0] * w[j, 1] * w[k, 2] * node_grad
        weight_grad = grid_velocity[grid_slot, q].dot(node_grad)
        x_grad += (inv_dx * weight_grad) * _weight_gradient(w, dw, i, j, k)
    return x_grad, Fc_grad


@ti.func
def p2g_particle_adjoint(
    xp, vp, Cp, stress_p, grid_mass_grad: ti.template(), grid_momentum_grad: ti.template(),
    grid_slot, n, dx, dt, particle_volume, particle_mass,
):  # fmt: skip
    """Reverse of :func:`p2g_particle`: from dL/d(grid mass) and dL/d(grid momentum), the
    particle's (dL/dx, dL/dv, dL/dC, dL/d stress)."""
    inv_dx = 1.0 / dx
    base, fx, w, dw = stencil_rows(xp, inv_dx, n)
    stress_scale = -dt * particle_volume * 4.0 * inv_dx * inv_dx
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
        weight_grad = particle_mass * grid_mass_grad[grid_slot, q] + momentum_grad.dot(
            momentum + matvec(affine, dpos)
        )
        x_grad += (inv_dx * weight_grad) * _weight_gradient(w, dw, i, j, k)
        weighted_grad = w[i, 0] * w[j, 1] * w[k, 2] * momentum_grad
        weighted += weighted_grad
        affine_grad += outer(weighted_grad, dpos)
    x_grad -= t_matvec(affine, weighted)
    return x_grad, particle_mass * weighted, particle_mass * affine_grad, stress_scale * affine_grad
