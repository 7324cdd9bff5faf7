"""Taichi kernels that move one MPM step's data between torch tensors and Taichi arrays.

Torch tensors are passed straight to ``ti.types.ndarray`` arguments (zero copy on the CPU);
every kernel reads or writes slot 0 (the step's input) or slot 1 (its output) of the
time-indexed Taichi arrays that :mod:`taichi_mpm.kernels.transfer` works on. Torch tensors are
plain (N, 3) / (N, 3, 3) arrays, so they are indexed element by element.
"""

import taichi as ti

from taichi_mpm.kernels.transfer import gather, scatter, update_node


@ti.func
def _vec(t: ti.template(), p):
    return ti.Vector([t[p, 0], t[p, 1], t[p, 2]], dt=float)


@ti.func
def _mat(t: ti.template(), p):
    return ti.Matrix(
        [[t[p, i, j] for j in ti.static(range(3))] for i in ti.static(range(3))], dt=float
    )


@ti.func
def _put_vec(t: ti.template(), p, value):
    for i in ti.static(range(3)):
        t[p, i] = value[i]


@ti.func
def _put_mat(t: ti.template(), p, value):
    for i, j in ti.static(ti.ndrange(3, 3)):
        t[p, i, j] = value[i, j]


@ti.kernel
def load_and_transfer(
    x_in: ti.types.ndarray(),
    v_in: ti.types.ndarray(),
    C_in: ti.types.ndarray(),
    F_in: ti.types.ndarray(),
    stress_in: ti.types.ndarray(),
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
    particle_volume: float,
    particle_mass: float,
    gx: float,
    gy: float,
    gz: float,
    wall_kind: ti.i32,
    wall_thickness: ti.i32,
    wall_friction: float,
    serial: ti.template(),
):
    """Copy the step's input into slot 0, then P2G, grid update and G2P into slot 1."""
    ti.loop_config(serialize=serial)
    for p in range(x.shape[1]):
        x[0, p] = _vec(x_in, p)
        v[0, p] = _vec(v_in, p)
        C[0, p] = _mat(C_in, p)
        F_corrected[0, p] = _mat(F_in, p)
        stress[0, p] = _mat(stress_in, p)
    n = grid_mass.shape[1]
    ti.loop_config(serialize=serial)
    for i, j, k in ti.ndrange(n, n, n):
        grid_mass[0, i, j, k] = 0.0
        grid_momentum[0, i, j, k] = ti.Vector.zero(float, 3)
    ti.loop_config(serialize=serial)
    for p in range(x.shape[1]):
        scatter(x, v, C, stress, 0, p, grid_mass, grid_momentum, dx, dt, particle_volume,
                particle_mass)  # fmt: skip
    ti.loop_config(serialize=serial)
    for i, j, k in ti.ndrange(n, n, n):
        update_node(grid_mass, grid_momentum, 0, i, j, k, grid_velocity, dt,
                    ti.Vector([gx, gy, gz]), wall_kind, wall_thickness, wall_friction)  # fmt: skip
    ti.loop_config(serialize=serial)
    for p in range(x.shape[1]):
        gather(x, v, C, F, F_corrected, grid_velocity, 0, p, dx, dt)


@ti.kernel
def store_state(
    x: ti.types.ndarray(),
    v: ti.types.ndarray(),
    C: ti.types.ndarray(),
    F: ti.types.ndarray(),
    x_out: ti.types.ndarray(),
    v_out: ti.types.ndarray(),
    C_out: ti.types.ndarray(),
    F_out: ti.types.ndarray(),
    serial: ti.template(),
):
    """Copy the state at slot 1 (the step's output) into torch tensors."""
    ti.loop_config(serialize=serial)
    for p in range(x.shape[1]):
        _put_vec(x_out, p, x[1, p])
        _put_vec(v_out, p, v[1, p])
        _put_mat(C_out, p, C[1, p])
        _put_mat(F_out, p, F[1, p])


@ti.kernel
def seed_output_gradients(
    x_grad_out: ti.types.ndarray(),
    v_grad_out: ti.types.ndarray(),
    C_grad_out: ti.types.ndarray(),
    F_grad_out: ti.types.ndarray(),
    x_grad: ti.types.ndarray(),
    v_grad: ti.types.ndarray(),
    C_grad: ti.types.ndarray(),
    F_grad: ti.types.ndarray(),
    F_corrected_grad: ti.types.ndarray(),
    stress_grad: ti.types.ndarray(),
    grid_mass_grad: ti.types.ndarray(),
    grid_momentum_grad: ti.types.ndarray(),
    grid_velocity_grad: ti.types.ndarray(),
    serial: ti.template(),
):
    """Clear every adjoint of the step, then seed slot 1 with dL/d(output)."""
    ti.loop_config(serialize=serial)
    for p in range(x_grad.shape[1]):
        x_grad[0, p] = ti.Vector.zero(float, 3)
        v_grad[0, p] = ti.Vector.zero(float, 3)
        C_grad[0, p] = ti.Matrix.zero(float, 3, 3)
        F_corrected_grad[0, p] = ti.Matrix.zero(float, 3, 3)
        stress_grad[0, p] = ti.Matrix.zero(float, 3, 3)
        x_grad[1, p] = _vec(x_grad_out, p)
        v_grad[1, p] = _vec(v_grad_out, p)
        C_grad[1, p] = _mat(C_grad_out, p)
        F_grad[1, p] = _mat(F_grad_out, p)
    n = grid_mass_grad.shape[1]
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
    x_grad_in: ti.types.ndarray(),
    v_grad_in: ti.types.ndarray(),
    C_grad_in: ti.types.ndarray(),
    F_grad_in: ti.types.ndarray(),
    stress_grad_in: ti.types.ndarray(),
    serial: ti.template(),
):
    """Copy dL/d(input) from the slot-0 adjoints into torch tensors."""
    ti.loop_config(serialize=serial)
    for p in range(x_grad.shape[1]):
        _put_vec(x_grad_in, p, x_grad[0, p])
        _put_vec(v_grad_in, p, v_grad[0, p])
        _put_mat(C_grad_in, p, C_grad[0, p])
        _put_mat(F_grad_in, p, F_corrected_grad[0, p])
        _put_mat(stress_grad_in, p, stress_grad[0, p])


@ti.kernel
def svd3(
    F: ti.types.ndarray(),
    U: ti.types.ndarray(),
    S: ti.types.ndarray(),
    V: ti.types.ndarray(),
    serial: ti.template(),
):
    """Signed SVD of a batch of 3x3 matrices, F = U diag(S) V^T with det U = det V = +1."""
    ti.loop_config(serialize=serial)
    for p in range(F.shape[0]):
        u, s, v = ti.svd(_mat(F, p))
        _put_mat(U, p, u)
        _put_mat(V, p, v)
        for i in ti.static(range(3)):
            S[p, i] = s[i, i]
