"""Taichi kernels that move one MPM step's data between torch tensors and Taichi arrays.

A Taichi launch costs ~25 us per torch-tensor argument on this CPU, more than the copy itself,
so each step's particle data crosses in one packed (B * N, 33) torch tensor (``COL_*``: x, v,
C, F, stress in row-major order) and comes back in one (B * N, 24) tensor (x, v, C, F). Torch
tensors are passed straight to ``ti.types.ndarray`` arguments (zero copy on the CPU).

A step may advance B independent copies of a scene at once (a batch: the segments of a
teacher-forced rollout), rows ``b * N .. (b + 1) * N - 1`` of the packed tensors being copy b.
Copy b lives in slots ``2 b`` (the step's input) and ``2 b + 1`` (its output) of the
time-indexed Taichi arrays that :mod:`taichi_mpm.kernels.transfer` works on, its grid in grid
slot ``2 b``: the transfer functions index particles and grid with the same slot, so every copy
keeps its own grid and walls. The differentiated kernels (:func:`p2g`, :func:`grid_update`,
:func:`g2p`) hold nothing but their loops, as Taichi's autodiff requires.
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
def _load_and_scatter(
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
    """Load the packed input into each copy's input slot, then P2G and the grid update (all
    the reverse pass needs recomputed: G2P's reverse reads only its inputs)."""
    dx, dt, volume, mass, gx, gy, gz, wall_kind, thickness, friction = settings
    B, N, n = x.shape[0] // 2, x.shape[1], grid_mass.shape[1]
    ti.loop_config(serialize=serial)
    for b, p in ti.ndrange(B, N):
        row = b * N + p
        x[2 * b, p] = _vec(packed, row, COL_X)
        v[2 * b, p] = _vec(packed, row, COL_V)
        C[2 * b, p] = _mat(packed, row, COL_C)
        F_corrected[2 * b, p] = _mat(packed, row, COL_F)
        stress[2 * b, p] = _mat(packed, row, COL_STRESS)
    ti.loop_config(serialize=serial)
    for b, i, j, k in ti.ndrange(B, n, n, n):
        grid_mass[2 * b, i, j, k] = 0.0
        grid_momentum[2 * b, i, j, k] = ti.Vector.zero(float, 3)
    ti.loop_config(serialize=serial)
    for b, p in ti.ndrange(B, N):
        scatter(x, v, C, stress, 2 * b, p, grid_mass, grid_momentum, dx, dt, volume, mass)
    ti.loop_config(serialize=serial)
    for b, i, j, k in ti.ndrange(B, n, n, n):
        update_node(grid_mass, grid_momentum, 2 * b, i, j, k, grid_velocity, dt,
                    ti.Vector([gx, gy, gz]), wall_kind, thickness, friction)  # fmt: skip


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
    """One step: packed (B * N, 33) input -> packed (B * N, 24) output (x, v, C, F_trial)."""
    _load_and_scatter(packed, x, v, C, F, F_corrected, stress, grid_mass, grid_momentum,
                      grid_velocity, (dx, dt, volume, mass, gx, gy, gz, wall_kind, thickness,
                      friction), serial)  # fmt: skip
    ti.loop_config(serialize=serial)
    for b, p in ti.ndrange(x.shape[0] // 2, x.shape[1]):
        gather(x, v, C, F, F_corrected, grid_velocity, 2 * b, p, dx, dt)
        row = b * x.shape[1] + p
        _put_vec(out, row, COL_X, x[2 * b + 1, p])
        _put_vec(out, row, COL_V, v[2 * b + 1, p])
        _put_mat(out, row, COL_C, C[2 * b + 1, p])
        _put_mat(out, row, COL_F, F[2 * b + 1, p])


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
    """Redo the step's P2G and grid update (the reverse pass reads the grid), clear the
    adjoints, seed dL/d(output)."""
    _load_and_scatter(packed, x, v, C, F, F_corrected, stress, grid_mass, grid_momentum,
                      grid_velocity, (dx, dt, volume, mass, gx, gy, gz, wall_kind, thickness,
                      friction), serial)  # fmt: skip
    ti.loop_config(serialize=serial)
    for b, p in ti.ndrange(x.shape[0] // 2, x.shape[1]):
        row = b * x.shape[1] + p
        x_grad[2 * b, p] = ti.Vector.zero(float, 3)
        v_grad[2 * b, p] = ti.Vector.zero(float, 3)
        C_grad[2 * b, p] = ti.Matrix.zero(float, 3, 3)
        F_corrected_grad[2 * b, p] = ti.Matrix.zero(float, 3, 3)
        stress_grad[2 * b, p] = ti.Matrix.zero(float, 3, 3)
        x_grad[2 * b + 1, p] = _vec(output_grad, row, COL_X)
        v_grad[2 * b + 1, p] = _vec(output_grad, row, COL_V)
        C_grad[2 * b + 1, p] = _mat(output_grad, row, COL_C)
        F_grad[2 * b + 1, p] = _mat(output_grad, row, COL_F)
    n = grid_mass.shape[1]
    ti.loop_config(serialize=serial)
    for b, i, j, k in ti.ndrange(x.shape[0] // 2, n, n, n):
        grid_mass_grad[2 * b, i, j, k] = 0.0
        grid_momentum_grad[2 * b, i, j, k] = ti.Vector.zero(float, 3)
        grid_velocity_grad[2 * b, i, j, k] = ti.Vector.zero(float, 3)


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
    """dL/d(input) from the input-slot adjoints into one packed (B * N, 33) torch tensor."""
    ti.loop_config(serialize=serial)
    for b, p in ti.ndrange(x_grad.shape[0] // 2, x_grad.shape[1]):
        row = b * x_grad.shape[1] + p
        _put_vec(input_grad, row, COL_X, x_grad[2 * b, p])
        _put_vec(input_grad, row, COL_V, v_grad[2 * b, p])
        _put_mat(input_grad, row, COL_C, C_grad[2 * b, p])
        _put_mat(input_grad, row, COL_F, F_corrected_grad[2 * b, p])
        _put_mat(input_grad, row, COL_STRESS, stress_grad[2 * b, p])


@ti.kernel
def p2g(
    x: ti.types.ndarray(),
    v: ti.types.ndarray(),
    C: ti.types.ndarray(),
    stress: ti.types.ndarray(),
    grid_mass: ti.types.ndarray(),
    grid_momentum: ti.types.ndarray(),
    dx: float,
    dt: float,
    volume: float,
    mass: float,
    serial: ti.template(),
):
    """P2G of every copy onto its own grid (differentiated by the backward pass)."""
    ti.loop_config(serialize=serial)
    for b, p in ti.ndrange(x.shape[0] // 2, x.shape[1]):
        scatter(x, v, C, stress, 2 * b, p, grid_mass, grid_momentum, dx, dt, volume, mass)


@ti.kernel
def grid_update(
    grid_mass: ti.types.ndarray(),
    grid_momentum: ti.types.ndarray(),
    grid_velocity: ti.types.ndarray(),
    dt: float,
    gx: float,
    gy: float,
    gz: float,
    wall_kind: ti.i32,
    thickness: ti.i32,
    friction: float,
    serial: ti.template(),
):
    """Grid update of every copy's grid (differentiated by the backward pass)."""
    ti.loop_config(serialize=serial)
    for b, i, j, k in ti.ndrange(
        grid_mass.shape[0] // 2, grid_mass.shape[1], grid_mass.shape[2], grid_mass.shape[3]
    ):
        update_node(grid_mass, grid_momentum, 2 * b, i, j, k, grid_velocity, dt,
                    ti.Vector([gx, gy, gz]), wall_kind, thickness, friction)  # fmt: skip


@ti.kernel
def g2p(
    x: ti.types.ndarray(),
    v: ti.types.ndarray(),
    C: ti.types.ndarray(),
    F: ti.types.ndarray(),
    F_corrected: ti.types.ndarray(),
    grid_velocity: ti.types.ndarray(),
    dx: float,
    dt: float,
    serial: ti.template(),
):
    """G2P of every copy from its own grid (differentiated by the backward pass)."""
    ti.loop_config(serialize=serial)
    for b, p in ti.ndrange(x.shape[0] // 2, x.shape[1]):
        gather(x, v, C, F, F_corrected, grid_velocity, 2 * b, p, dx, dt)


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


@ti.func
def _clamp_magnitude(x, tol):
    return ti.max(x, tol) if x >= 0 else ti.min(x, -tol)


@ti.kernel
def svd3_backward(
    U: ti.types.ndarray(),
    S: ti.types.ndarray(),
    Vh: ti.types.ndarray(),
    U_grad: ti.types.ndarray(),
    S_grad: ti.types.ndarray(),
    Vh_grad: ti.types.ndarray(),
    F_grad: ti.types.ndarray(),
    tol_factor: float,
    serial: ti.template(),
):
    """dL/dF of F = U diag(S) Vh from dL/dU, dL/dS, dL/dVh, rows of (B, 9) / (B, 3) arrays.

    The clamped formula of :mod:`bridges.linalg` in one pass per matrix:
    ``U (sym(a + b) / (s_j - s_i) + (a - b) / (s_j + s_i)) / 2 + diag(dL/dS)) Vh``, each
    denominator's magnitude at least ``tol_factor * max(1, max_k |s_k|)``.
    """
    ti.loop_config(serialize=serial)
    for p in range(U.shape[0]):
        u, vh = _mat(U, p, 0), _mat(Vh, p, 0)
        s = ti.Vector([S[p, 0], S[p, 1], S[p, 2]], dt=float)
        a = u.transpose() @ _mat(U_grad, p, 0)
        b = vh @ _mat(Vh_grad, p, 0).transpose()
        a, b = a - a.transpose(), b - b.transpose()
        tol = tol_factor * ti.max(1.0, ti.max(ti.abs(s[0]), ti.abs(s[1]), ti.abs(s[2])))
        inner = ti.Matrix.zero(float, 3, 3)
        for i, j in ti.static(ti.ndrange(3, 3)):
            if ti.static(i == j):
                inner[i, j] = S_grad[p, i]
            else:
                gap = _clamp_magnitude(s[j] - s[i], tol)
                total = _clamp_magnitude(s[j] + s[i], tol)
                inner[i, j] = 0.5 * ((a[i, j] + b[i, j]) / gap + (a[i, j] - b[i, j]) / total)
        _put_mat(F_grad, p, 0, u @ inner @ vh)
