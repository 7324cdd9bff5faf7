"""Taichi kernels that move one MPM step's data between torch tensors and Taichi arrays.

A Taichi launch costs ~25 us per torch-tensor argument on this CPU, more than the copy itself,
so each step's particle data crosses in one packed (N, 33) torch tensor (``COL_*``: x, v, C,
F, stress in row-major order) and comes back in one (N, 24) tensor (x, v, C, F). Torch tensors
are passed straight to ``ti.types.ndarray`` arguments (zero copy on the CPU); the kernels read
slot 0 (the step's input) and write slot 1 (its output) of the time-indexed Taichi arrays that
:mod:`taichi_mpm.kernels.transfer` works on.
"""

import taichi as ti

from taichi_mpm.kernels.transfer import gather, scatter, update_node

#: Column offsets of the packed per-particle rows.
COL_X, COL_V, COL_C, COL_F, COL_STRESS = 0, 3, 6, 15, 24
STATE_WIDTH, PACKED_WIDTH = 24, 33


@ti.func
def _vec(t: ti.template(), p, offset):
    return ti.Vector([t[p, offset + i] for i in ti.static(range(3))], dt=float)


@ti.func
def _mat(t: ti.template(), p, offset):
    return ti.Matrix(
        [[t[p, offset + 3 * i + j] for j in ti.static(range(3))] for i in ti.static(range(3))],
        dt=float,
    )


@ti.func
def _put_vec(t: ti.template(), p, offset, value):
    for i in ti.static(range(3)):
        t[p, offset + i] = value[i]


@ti.func
def _put_mat(t: ti.template(), p, offset, value):
    for i, j in ti.static(ti.ndrange(3, 3)):
        t[p, offset + 3 * i + j] = value[i, j]


@ti.func
def _transfer(
    packed: ti.template(),
    x: ti.template(),
    v: ti.template(),
    C: ti.template(),
    F: ti.template(),
    F_corrected: ti.template(),
    stress: ti.template(),
    grid_mass: ti.template(),
    grid_momentum: ti.template(),
    grid_velocity: ti.template(),
    settings: ti.template(),
    serial: ti.template(),
):
    """Load the packed input into slot 0, then P2G, grid update and G2P into slot 1."""
    dx, dt, volume, mass, gx, gy, gz, wall_kind, thickness, friction = settings
    ti.loop_config(serialize=serial)
    for p in range(x.shape[1]):
        x[0, p] = _vec(packed, p, COL_X)
        v[0, p] = _vec(packed, p, COL_V)
        C[0, p] = _mat(packed, p, COL_C)
        F_corrected[0, p] = _mat(packed, p, COL_F)
        stress[0, p] = _mat(packed, p, COL_STRESS)
    n = grid_mass.shape[1]
    ti.loop_config(serialize=serial)
    for i, j, k in ti.ndrange(n, n, n):
        grid_mass[0, i, j, k] = 0.0
        grid_momentum[0, i, j, k] = ti.Vector.zero(float, 3)
    ti.loop_config(serialize=serial)
    for p in range(x.shape[1]):
        scatter(x, v, C, stress, 0, p, grid_mass, grid_momentum, dx, dt, volume, mass)
    ti.loop_config(serialize=serial)
    for i, j, k in ti.ndrange(n, n, n):
        update_node(grid_mass, grid_momentum, 0, i, j, k, grid_velocity, dt,
                    ti.Vector([gx, gy, gz]), wall_kind, thickness, friction)  # fmt: skip
    ti.loop_config(serialize=serial)
    for p in range(x.shape[1]):
        gather(x, v, C, F, F_corrected, grid_velocity, 0, p, dx, dt)


@ti.kernel
def step_forward(
    packed: ti.types.ndarray(),
    out: ti.types.ndarray(),
    x: ti.types.ndarray(),
    v: ti.types.ndarray(),
    C: ti.types.ndarray(),
    F: ti.types.ndarray(),
    F_corrected: ti.types.ndarray(),
    stress: ti.types.ndarray(),
    grid_mass: ti.types.ndarray(),
    grid_momentum: ti.types.ndarray(),
    grid_velocity: ti.types.ndarray(),
    dx: float,
    dt: float,
    volume: float,
    mass: float,
    gx: float,
    gy: float,
    gz: float,
    wall_kind: ti.i32,
    thickness: ti.i32,
    friction: float,
    serial: ti.template(),
):
    """One step: packed (N, 33) input -> packed (N, 24) output (x, v, C, F_trial)."""
    _transfer(packed, x, v, C, F, F_corrected, stress, grid_mass, grid_momentum, grid_velocity,
              (dx, dt, volume, mass, gx, gy, gz, wall_kind, thickness, friction),
              serial)  # fmt: skip
    ti.loop_config(serialize=serial)
    for p in range(x.shape[1]):
        _put_vec(out, p, COL_X, x[1, p])
        _put_vec(out, p, COL_V, v[1, p])
        _put_mat(out, p, COL_C, C[1, p])
        _put_mat(out, p, COL_F, F[1, p])


@ti.kernel
def recompute_and_seed(
    packed: ti.types.ndarray(),
    output_grad: ti.types.ndarray(),
    x: ti.types.ndarray(),
    v: ti.types.ndarray(),
    C: ti.types.ndarray(),
    F: ti.types.ndarray(),
    F_corrected: ti.types.ndarray(),
    stress: ti.types.ndarray(),
    grid_mass: ti.types.ndarray(),
    grid_momentum: ti.types.ndarray(),
    grid_velocity: ti.types.ndarray(),
    x_grad: ti.types.ndarray(),
    v_grad: ti.types.ndarray(),
    C_grad: ti.types.ndarray(),
    F_grad: ti.types.ndarray(),
    F_corrected_grad: ti.types.ndarray(),
    stress_grad: ti.types.ndarray(),
    grid_mass_grad: ti.types.ndarray(),
    grid_momentum_grad: ti.types.ndarray(),
    grid_velocity_grad: ti.types.ndarray(),
    dx: float,
    dt: float,
    volume: float,
    mass: float,
    gx: float,
    gy: float,
    gz: float,
    wall_kind: ti.i32,
    thickness: ti.i32,
    friction: float,
    serial: ti.template(),
):
    """Redo the step's forward (its grid is needed), clear all adjoints, seed dL/d(output)."""
    _transfer(packed, x, v, C, F, F_corrected, stress, grid_mass, grid_momentum, grid_velocity,
              (dx, dt, volume, mass, gx, gy, gz, wall_kind, thickness, friction),
              serial)  # fmt: skip
    ti.loop_config(serialize=serial)
    for p in range(x.shape[1]):
        x_grad[0, p] = ti.Vector.zero(float, 3)
        v_grad[0, p] = ti.Vector.zero(float, 3)
        C_grad[0, p] = ti.Matrix.zero(float, 3, 3)
        F_corrected_grad[0, p] = ti.Matrix.zero(float, 3, 3)
        stress_grad[0, p] = ti.Matrix.zero(float, 3, 3)
        x_grad[1, p] = _vec(output_grad, p, COL_X)
        v_grad[1, p] = _vec(output_grad, p, COL_V)
        C_grad[1, p] = _mat(output_grad, p, COL_C)
        F_grad[1, p] = _mat(output_grad, p, COL_F)
    n = grid_mass.shape[1]
    ti.loop_config(serialize=serial)
    for i, j, k in ti.ndrange(n, n, n):
        grid_mass_grad[0, i, j, k] = 0.0
        grid_momentum_grad[0, i, j, k] = ti.Vector.zero(float, 3)
        grid_velocity_grad[0, i, j, k] = ti.Vector.zero(float, 3)


@ti.kernel
def store_input_gradients(
    x_grad: ti.types.ndarray(),
    v_grad: ti.types.ndarray(),
    C_grad: ti.types.ndarray(),
    F_corrected_grad: ti.types.ndarray(),
    stress_grad: ti.types.ndarray(),
    input_grad: ti.types.ndarray(),
    serial: ti.template(),
):
    """dL/d(input) from the slot-0 adjoints into one packed (N, 33) torch tensor."""
    ti.loop_config(serialize=serial)
    for p in range(x_grad.shape[1]):
        _put_vec(input_grad, p, COL_X, x_grad[0, p])
        _put_vec(input_grad, p, COL_V, v_grad[0, p])
        _put_mat(input_grad, p, COL_C, C_grad[0, p])
        _put_mat(input_grad, p, COL_F, F_corrected_grad[0, p])
        _put_mat(input_grad, p, COL_STRESS, stress_grad[0, p])


@ti.kernel
def svd3(F: ti.types.ndarray(), out: ti.types.ndarray(), serial: ti.template()):
    """Signed SVD of (B, 9) row-major 3x3 matrices into (B, 21) rows: U (9), S (3), V (9).

    F = U diag(S) V^T with det U = det V = +1.
    """
    ti.loop_config(serialize=serial)
    for p in range(F.shape[0]):
        u, s, v = ti.svd(_mat(F, p, 0))
        _put_mat(out, p, 0, u)
        for i in ti.static(range(3)):
            out[p, 9 + i] = s[i, i]
        _put_mat(out, p, 12, v)
