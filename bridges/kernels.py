"""Taichi kernels of one MPM step on torch tensors, and their hand-written reverse.

A Taichi launch costs ~25 us per torch-tensor argument on this CPU, more than the copy itself,
so each step's particle data crosses in one packed (B * N, 33) torch tensor (``COL_*``: x, v,
C, F, stress in row-major order) and comes back in one (B * N, 24) tensor (x, v, C, F). Torch
tensors are passed straight to ``ti.types.ndarray`` arguments (zero copy on the CPU), and the
kernels read and write them directly: only the grids live in Taichi arrays.

A step may advance B independent copies of a scene at once (a batch: the segments of a
teacher-forced rollout), rows ``b * N .. (b + 1) * N - 1`` of the packed tensors being copy b,
its grid row b of the (B, n^3) grid arrays, so every copy keeps its own grid and walls.

With serial loops (a CPU step below ``bridges.step.PARALLEL_MIN_PARTICLES``), grid loops visit
only each copy's occupied box: the nodes of its particles' stencils, measured at the start of
every launch into ``box`` (B, 6: lower corner, upper corner exclusive). A launch clears and
writes every node of the boxes before reading any, and reads nothing outside them, so nodes
outside keep stale values that are never used. In the paper scene a box is about a fifth of
the grid. Parallel loops visit every node.

The reverse pass is one launch, :func:`step_backward`: it redoes the step's P2G and grid update
(the reverse reads the grid), then runs the hand-written adjoints
(:mod:`taichi_mpm.kernels.transfer_adjoint`) of G2P, of the grid update (walls included) and
of P2G. The per-particle and per-node functions are those of
:mod:`taichi_mpm.kernels.transfer`, which ``taichi_mpm.Simulator`` differentiates with Taichi's
autodiff instead.
"""

import taichi as ti

from taichi_mpm.kernels.jacobi_svd import jacobi_svd
from taichi_mpm.kernels.transfer import (
    g2p_particle,
    node_index,
    p2g_particle,
    stencil,
    update_node,
)
from taichi_mpm.kernels.transfer_adjoint import (
    g2p_particle_adjoint,
    p2g_particle_adjoint,
    update_node_adjoint,
)

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
def _measure_boxes(packed: ti.template(), box: ti.template(), n, dx):
    """Each copy's occupied box (serial loops only): from the lowest to past the highest node
    of its particles' 27-node stencils."""
    B = box.shape[0]
    N = packed.shape[0] // B
    ti.loop_config(serialize=True)
    for b in range(B):
        lower = ti.Vector([n, n, n])
        upper = ti.Vector([0, 0, 0])
        for p in range(N):
            base, _fx, _w = stencil(_vec(packed, b * N + p, COL_X), 1.0 / dx, n)
            lower = ti.min(lower, base)
            upper = ti.max(upper, base + 3)
        for d in ti.static(range(3)):
            box[b, d] = lower[d]
            box[b, 3 + d] = upper[d]


@ti.func
def _each_node(body: ti.template(), before: ti.template(), after: ti.template(),
               box: ti.template(), B, nodes, n, serial: ti.template()):  # fmt: skip
    """``body(*before, b, q, *after)`` for node q of every copy b: the nodes of the copies'
    boxes with serial loops, every node with parallel ones."""
    if ti.static(serial):
        ti.loop_config(serialize=True)
        for b in range(B):
            for i in range(box[b, 0], box[b, 3]):
                for j in range(box[b, 1], box[b, 4]):
                    for k in range(box[b, 2], box[b, 5]):
                        body(*before, b, node_index(i, j, k, n), *after)
    else:
        for b, q in ti.ndrange(B, nodes):
            body(*before, b, q, *after)


@ti.func
def _clear_node(grid_mass: ti.template(), grid_momentum: ti.template(), b, q):
    grid_mass[b, q] = 0.0
    grid_momentum[b, q] = ti.Vector.zero(float, 3)


@ti.func
def _clear_velocity_grad(grid_velocity_grad: ti.template(), b, q):
    grid_velocity_grad[b, q] = ti.Vector.zero(float, 3)


@ti.func
def _scatter_and_update(
    packed: ti.template(),
    grid_mass: ti.template(),
    grid_momentum: ti.template(),
    grid_velocity: ti.template(),
    box: ti.template(),
    settings: ti.template(),
    serial: ti.template(),
):
    """Clear every copy's grid (its box), P2G of the packed input, the grid update."""
    n, dx, dt, volume, mass, gx, gy, gz, wall_kind, thickness, friction = settings
    B, nodes = grid_mass.shape[0], grid_mass.shape[1]
    N = packed.shape[0] // B
    if ti.static(serial):
        _measure_boxes(packed, box, n, dx)
    _each_node(_clear_node, (grid_mass, grid_momentum), (), box, B, nodes, n, serial)
    ti.loop_config(serialize=serial)
    for b, p in ti.ndrange(B, N):
        row = b * N + p
        p2g_particle(_vec(packed, row, COL_X), _vec(packed, row, COL_V),
                     _mat(packed, row, COL_C), _mat(packed, row, COL_STRESS), grid_mass,
                     grid_momentum, b, n, dx, dt, volume, mass)  # fmt: skip
    _each_node(update_node, (grid_mass, grid_momentum),
               (n, grid_velocity, dt, ti.Vector([gx, gy, gz]), wall_kind, thickness, friction),
               box, B, nodes, n, serial)  # fmt: skip


@ti.kernel
def step_forward(
    packed: ti.types.ndarray(),
    out: ti.types.ndarray(),
    grid_mass: ti.types.ndarray(),
    grid_momentum: ti.types.ndarray(),
    grid_velocity: ti.types.ndarray(),
    box: ti.types.ndarray(),
    n: ti.i32,
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
    _scatter_and_update(packed, grid_mass, grid_momentum, grid_velocity, box,
                        (n, dx, dt, volume, mass, gx, gy, gz, wall_kind, thickness, friction),
                        serial)  # fmt: skip
    B = grid_mass.shape[0]
    N = packed.shape[0] // B
    ti.loop_config(serialize=serial)
    for b, p in ti.ndrange(B, N):
        row = b * N + p
        new_x, new_v, new_C, new_F = g2p_particle(_vec(packed, row, COL_X),
                                                  _mat(packed, row, COL_F), grid_velocity, b, n,
                                                  dx, dt)  # fmt: skip
        _put_vec(out, row, COL_X, new_x)
        _put_vec(out, row, COL_V, new_v)
        _put_mat(out, row, COL_C, new_C)
        _put_mat(out, row, COL_F, new_F)


@ti.kernel
def step_backward(
    packed: ti.types.ndarray(),
    output: ti.types.ndarray(),
    output_grad: ti.types.ndarray(),
    input_grad: ti.types.ndarray(),
    grid_mass: ti.types.ndarray(),
    grid_momentum: ti.types.ndarray(),
    grid_velocity: ti.types.ndarray(),
    grid_mass_grad: ti.types.ndarray(),
    grid_momentum_grad: ti.types.ndarray(),
    grid_velocity_grad: ti.types.ndarray(),
    box: ti.types.ndarray(),
    n: ti.i32,
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
    """A step's reverse: the packed (B * N, 33) ``input_grad`` (dL/d x, v, C, F, stress) from
    the (B * N, 24) ``output_grad``, given the step's (B * N, 24) ``output``. Redoes P2G and
    the grid update, then runs the adjoints of G2P, the grid update and P2G in turn."""
    _scatter_and_update(packed, grid_mass, grid_momentum, grid_velocity, box,
                        (n, dx, dt, volume, mass, gx, gy, gz, wall_kind, thickness, friction),
                        serial)  # fmt: skip
    B, nodes = grid_mass.shape[0], grid_mass.shape[1]
    N = packed.shape[0] // B
    _each_node(_clear_velocity_grad, (grid_velocity_grad,), (), box, B, nodes, n, serial)
    ti.loop_config(serialize=serial)
    for b, p in ti.ndrange(B, N):
        row = b * N + p
        x_grad, F_grad = g2p_particle_adjoint(
            _vec(packed, row, COL_X), _mat(packed, row, COL_F), _vec(output, row, COL_V),
            _mat(output, row, COL_C), grid_velocity, grid_velocity_grad, b, n, dx, dt,
            _vec(output_grad, row, COL_X),
            _vec(output_grad, row, COL_V), _mat(output_grad, row, COL_C),
            _mat(output_grad, row, COL_F),
        )  # fmt: skip
        _put_vec(input_grad, row, COL_X, x_grad)
        _put_mat(input_grad, row, COL_F, F_grad)
    _each_node(update_node_adjoint,
               (grid_mass, grid_momentum, grid_velocity_grad, grid_mass_grad, grid_momentum_grad),
               (n, dt, ti.Vector([gx, gy, gz]), wall_kind, thickness, friction),
               box, B, nodes, n, serial)  # fmt: skip
    ti.loop_config(serialize=serial)
    for b, p in ti.ndrange(B, N):
        row = b * N + p
        x_grad, v_grad, C_grad, stress_grad = p2g_particle_adjoint(
            _vec(packed, row, COL_X), _vec(packed, row, COL_V), _mat(packed, row, COL_C),
            _mat(packed, row, COL_STRESS), grid_mass_grad, grid_momentum_grad, b, n, dx, dt,
            volume, mass,
        )  # fmt: skip
        _put_vec(input_grad, row, COL_X, _vec(input_grad, row, COL_X) + x_grad)
        _put_vec(input_grad, row, COL_V, v_grad)
        _put_mat(input_grad, row, COL_C, C_grad)
        _put_mat(input_grad, row, COL_STRESS, stress_grad)


@ti.kernel
def svd3(F: ti.types.ndarray(), out: ti.types.ndarray(), serial: ti.template()):
    """Signed SVD of (B, 9) row-major 3x3 matrices into (B, 21) rows: U (9), S (3), V (9).

    F = U diag(S) V^T with det U = det V = +1.
    """
    ti.loop_config(serialize=serial)
    for p in range(F.shape[0]):
        u, s, v = jacobi_svd(_mat(F, p, 0))
        _put_mat(out, p, 0, u)
        for i in ti.static(range(3)):
            out[p, 9 + i] = s[i]
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
