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

They are checked against Taichi's autodiff of the forward functions (taichi_mpm's reverse
pass) and against finite differences in ``tests/bridges``.
"""

import taichi as ti

from taichi_mpm.kernels.linalg import identity, matmul_t, matvec, outer, t_matmul, t_matvec
from taichi_mpm.kernels.transfer import STENCIL, node_index, stencil


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
    grid_slot, n, dx, dt, x_out_grad, v_out_grad, C_out_grad, F_out_grad,
):  # fmt: skip
    """Reverse of :func:`~taichi_mpm.kernels.transfer.g2p_particle` (whose results ``new_v``
    and ``new_C`` it takes): adds dL/d(grid velocity) into ``grid_velocity_grad`` and returns
    (dL/dx, dL/dFc) of the particle."""
    inv_dx = 1.0 / dx
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
def p2g_particle_adjoint(
    xp, vp, Cp, stress_p, grid_mass_grad: ti.template(), grid_momentum_grad: ti.template(),
    grid_slot, n, dx, dt, particle_volume, particle_mass,
):  # fmt: skip
    """Reverse of :func:`~taichi_mpm.kernels.transfer.p2g_particle`: from dL/d(grid mass) and
    dL/d(grid momentum), the particle's (dL/dx, dL/dv, dL/dC, dL/d stress)."""
    inv_dx = 1.0 / dx
    base, fx, w = stencil(xp, inv_dx, n)
    dw = _weight_slopes(fx)
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
        weight = w[i][0] * w[j][1] * w[k][2]
        weight_grad = particle_mass * grid_mass_grad[grid_slot, q] + momentum_grad.dot(
            momentum + matvec(affine, dpos)
        )
        x_grad += (inv_dx * weight_grad) * _weight_gradient(w, dw, i, j, k)
        weighted += weight * momentum_grad
        affine_grad += outer(weight * momentum_grad, dpos)
    x_grad -= t_matvec(affine, weighted)
    return x_grad, particle_mass * weighted, particle_mass * affine_grad, stress_scale * affine_grad
