"""Taichi kernels of one MPM step on torch tensors, and their hand-written reverse.

Each torch-tensor argument adds to a Taichi launch's cost, more than the copy itself costs, so
each step's particle data crosses in one packed (B * N, 33) torch tensor (``COL_*``: x, v,
C, F, stress in row-major order) and comes back in two: the (B * N, 15) motion (x, v, C) and
the (B * N, 9) trial F, which the graph need not keep once the plastic law has read it. Torch
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

The reverse pass is one launch, ``backward``: it redoes the step's P2G and grid update (the
reverse reads the grid), then runs the hand-written adjoints
(:mod:`taichi_mpm.kernels.transfer_adjoint`) of G2P, of the grid update (walls included) and
of P2G. The per-particle and per-node functions are those of
:mod:`taichi_mpm.kernels.transfer`, which ``taichi_mpm.Simulator`` differentiates with Taichi's
autodiff instead. Both step kernels take the grids as :data:`~taichi_mpm.kernels.arguments.Grid`
packs and the step's constants as one pack (``taichi_mpm.kernels.arguments.step_constants``),
and are made once per precision (:func:`step_kernels`).
"""

import functools
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import taichi as ti

from taichi_mpm.front_end import shorten_positions_under
from taichi_mpm.kernels import arguments
from taichi_mpm.kernels.arguments import CARRIED, Grid, GridGrad
from taichi_mpm.kernels.constitutive import J_FLOOR, SIGMA_FLOOR
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

shorten_positions_under(Path(__file__).parent)

#: The fields of a packed input row, in order, and their shapes per particle: the state a step
#: carries (``CARRIED``: x, v, C, F), then the Kirchhoff stress. The fields' first columns:
INPUT_FIELDS = {**CARRIED, "stress": (3, 3)}
COL_X, COL_V, COL_C, COL_F, COL_STRESS = 0, 3, 6, 15, 24
STATE_WIDTH, PACKED_WIDTH = 24, 33
#: A step writes the carried state as two arrays: the motion (x, v, C), which the next step's
#: reverse reads, in rows of ``MOTION_WIDTH`` with x, v and C at their input columns, and the
#: trial F in rows of 9, which only the plastic law reads (so the graph need not keep it).
MOTION_FIELDS = ("x", "v", "C")
MOTION_WIDTH = COL_F


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
def _measure_boxes(packed: ti.template(), box: ti.template(), constants: ti.template()):
    """Each copy's occupied box (serial loops only): from the lowest to past the highest node
    of its particles' 27-node stencils."""
    n = constants.grid_resolution
    B = box.shape[0]
    N = packed.shape[0] // B
    ti.loop_config(serialize=True)
    for b in range(B):
        lower = ti.Vector([n, n, n])
        upper = ti.Vector([0, 0, 0])
        for p in range(N):
            base, _fx, _w = stencil(_vec(packed, b * N + p, COL_X), 1.0 / constants.dx, n)
            lower = ti.min(lower, base)
            upper = ti.max(upper, base + 3)
        for d in ti.static(range(3)):
            box[b, d] = lower[d]
            box[b, 3 + d] = upper[d]


@ti.func
def _each_node(body: ti.template(), before: ti.template(), after: ti.template(),
               box: ti.template(), nodes, n, serial: ti.template()):  # fmt: skip
    """``body(*before, b, q, *after)`` for node q of every copy b (a row of ``box``): the nodes
    of the copies' boxes with serial loops, all ``nodes`` with parallel ones."""
    if ti.static(serial):
        ti.loop_config(serialize=True)
        for b in range(box.shape[0]):
            for i in range(box[b, 0], box[b, 3]):
                for j in range(box[b, 1], box[b, 4]):
                    for k in range(box[b, 2], box[b, 5]):
                        body(*before, b, node_index(i, j, k, n), *after)
    else:
        for b, q in ti.ndrange(box.shape[0], nodes):
            body(*before, b, q, *after)


@ti.func
def _clear_node(grid_mass: ti.template(), grid_momentum: ti.template(), b, q):
    grid_mass[b, q] = 0.0
    grid_momentum[b, q] = ti.Vector.zero(float, 3)


@ti.func
def _clear_velocity_grad(grid_velocity_grad: ti.template(), b, q):
    grid_velocity_grad[b, q] = ti.Vector.zero(float, 3)


@ti.func
def _scatter_and_update(packed: ti.template(), grid: ti.template(), box: ti.template(),
                        constants: ti.template(), serial: ti.template()):  # fmt: skip
    """Clear every copy's grid (its box), P2G of the packed input, the grid update."""
    n = constants.grid_resolution
    B, nodes = grid.mass.shape[0], grid.mass.shape[1]
    N = packed.shape[0] // B
    if ti.static(serial):
        _measure_boxes(packed, box, constants)
    _each_node(_clear_node, (grid.mass, grid.momentum), (), box, nodes, n, serial)
    ti.loop_config(serialize=serial)
    for b, p in ti.ndrange(B, N):
        row = b * N + p
        p2g_particle(_vec(packed, row, COL_X), _vec(packed, row, COL_V),
                     _mat(packed, row, COL_C), _mat(packed, row, COL_STRESS), grid.mass,
                     grid.momentum, b, constants)  # fmt: skip
    _each_node(update_node, (grid.mass, grid.momentum, grid.velocity), (constants,), box, nodes,
               n, serial)  # fmt: skip


@dataclass(frozen=True)
class StepKernels:
    """A bridge step's kernels for one precision.

    ``forward(packed, motion, trial_F, grid, box, constants, serial)``: one step, packed
    (B * N, 33) input -> (B * N, 15) ``motion`` (x, v, C) and (B * N, 9) ``trial_F``.

    ``backward(packed, motion, output_grad, input_grad, grid, grid_grad, box, constants,
    serial)``: a step's reverse, the packed (B * N, 33) ``input_grad`` (dL/d x, v, C, F,
    stress) from the (B * N, 24) ``output_grad`` (x, v, C, F_trial), given the step's
    (B * N, 15) output ``motion``.
    Redoes P2G and the grid update, then runs the adjoints of G2P, the grid update and P2G in
    turn; ``grid_grad`` holds dL/d(grid mass, momentum, velocity).

    ``grid`` and ``grid_grad`` are :data:`~taichi_mpm.kernels.arguments.Grid` and
    :data:`~taichi_mpm.kernels.arguments.GridGrad` packs of (B, n^3) arrays, ``box`` the (B, 6)
    occupied boxes, ``serial`` compile-time.
    """

    forward: Callable
    backward: Callable


@functools.cache
def step_kernels(dtype) -> StepKernels:
    """:class:`StepKernels` whose ``constants`` are in ``dtype``."""
    Constants = arguments.model_types(dtype).constants

    @ti.kernel
    def step_forward(packed: ti.types.ndarray(), motion: ti.types.ndarray(),
                     trial_F: ti.types.ndarray(), grid: Grid, box: ti.types.ndarray(),
                     constants: Constants, serial: ti.template()):  # fmt: skip
        _scatter_and_update(packed, grid, box, constants, serial)
        B = grid.mass.shape[0]
        N = packed.shape[0] // B
        ti.loop_config(serialize=serial)
        for b, p in ti.ndrange(B, N):
            row = b * N + p
            new_x, new_v, new_C, new_F = g2p_particle(_vec(packed, row, COL_X),
                                                      _mat(packed, row, COL_F), grid.velocity, b,
                                                      constants)  # fmt: skip
            _put_vec(motion, row, COL_X, new_x)
            _put_vec(motion, row, COL_V, new_v)
            _put_mat(motion, row, COL_C, new_C)
            _put_mat(trial_F, row, 0, new_F)

    @ti.kernel
    def step_backward(packed: ti.types.ndarray(), motion: ti.types.ndarray(),
                      output_grad: ti.types.ndarray(), input_grad: ti.types.ndarray(),
                      grid: Grid, grid_grad: GridGrad, box: ti.types.ndarray(),
                      constants: Constants, serial: ti.template()):  # fmt: skip
        _scatter_and_update(packed, grid, box, constants, serial)
        B, nodes = grid.mass.shape[0], grid.mass.shape[1]
        N = packed.shape[0] // B
        n = constants.grid_resolution
        _each_node(_clear_velocity_grad, (grid_grad.velocity_grad,), (), box, nodes, n, serial)
        ti.loop_config(serialize=serial)
        for b, p in ti.ndrange(B, N):
            row = b * N + p
            x_grad, F_grad = g2p_particle_adjoint(
                _vec(packed, row, COL_X), _mat(packed, row, COL_F), _vec(motion, row, COL_V),
                _mat(motion, row, COL_C), grid.velocity, grid_grad.velocity_grad, b, constants,
                _vec(output_grad, row, COL_X), _vec(output_grad, row, COL_V),
                _mat(output_grad, row, COL_C), _mat(output_grad, row, COL_F),
            )  # fmt: skip
            _put_vec(input_grad, row, COL_X, x_grad)
            _put_mat(input_grad, row, COL_F, F_grad)
        _each_node(update_node_adjoint,
                   (grid.mass, grid.momentum, grid_grad.velocity_grad, grid_grad.mass_grad,
                    grid_grad.momentum_grad), (constants,), box, nodes, n, serial)  # fmt: skip
        ti.loop_config(serialize=serial)
        for b, p in ti.ndrange(B, N):
            row = b * N + p
            x_grad, v_grad, C_grad, stress_grad = p2g_particle_adjoint(
                _vec(packed, row, COL_X), _vec(packed, row, COL_V), _mat(packed, row, COL_C),
                _mat(packed, row, COL_STRESS), grid_grad.mass_grad, grid_grad.momentum_grad, b,
                constants,
            )  # fmt: skip
            _put_vec(input_grad, row, COL_X, _vec(input_grad, row, COL_X) + x_grad)
            _put_vec(input_grad, row, COL_V, v_grad)
            _put_mat(input_grad, row, COL_C, C_grad)
            _put_mat(input_grad, row, COL_STRESS, stress_grad)

    return StepKernels(step_forward, step_backward)


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


@ti.func
def _svd_adjoint(u, s, vh, u_grad, s_grad, vh_grad, tol_factor):
    """dL/dF of F = U diag(s) Vh from dL/dU, dL/ds, dL/dVh: the clamped formula of
    :mod:`bridges.linalg`, ``U (sym(a + b) / (s_j - s_i) + (a - b) / (s_j + s_i)) / 2 +
    diag(dL/ds)) Vh``, each denominator's magnitude at least
    ``tol_factor * max(1, max_k |s_k|)``."""
    a = u.transpose() @ u_grad
    b = vh @ vh_grad.transpose()
    a, b = a - a.transpose(), b - b.transpose()
    tol = tol_factor * ti.max(1.0, ti.max(ti.abs(s[0]), ti.abs(s[1]), ti.abs(s[2])))
    inner = ti.Matrix.zero(float, 3, 3)
    for i, j in ti.static(ti.ndrange(3, 3)):
        if ti.static(i == j):
            inner[i, j] = s_grad[i]
        else:
            gap = _clamp_magnitude(s[j] - s[i], tol)
            total = _clamp_magnitude(s[j] + s[i], tol)
            inner[i, j] = 0.5 * ((a[i, j] + b[i, j]) / gap + (a[i, j] - b[i, j]) / total)
    return u @ inner @ vh


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
    """dL/dF of F = U diag(S) Vh from dL/dU, dL/dS, dL/dVh, rows of (B, 9) / (B, 3) arrays,
    by :func:`_svd_adjoint`."""
    ti.loop_config(serialize=serial)
    for p in range(U.shape[0]):
        s = ti.Vector([S[p, 0], S[p, 1], S[p, 2]], dt=float)
        s_grad = ti.Vector([S_grad[p, 0], S_grad[p, 1], S_grad[p, 2]], dt=float)
        F_grad_p = _svd_adjoint(_mat(U, p, 0), s, _mat(Vh, p, 0), _mat(U_grad, p, 0), s_grad,
                                _mat(Vh_grad, p, 0), tol_factor)  # fmt: skip
        _put_mat(F_grad, p, 0, F_grad_p)


#: Columns of a compact signed SVD row: U as a unit quaternion (w, x, y, z), the three signed
#: singular values, V as a unit quaternion. 11 numbers where the matrices take 21: a Hencky
#: stress's reverse keeps one such row a particle and step.
COMPACT_SVD_WIDTH = 11


@ti.func
def _quaternion(r):
    """The unit quaternion (w, x, y, z) of the rotation ``r``, by Shepperd's method: from the
    largest of 1 + trace and the three 1 + 2 r_ii - trace, so nothing is divided by a small
    number."""
    trace = r[0, 0] + r[1, 1] + r[2, 2]
    q = ti.Vector.zero(float, 4)
    if trace >= r[0, 0] and trace >= r[1, 1] and trace >= r[2, 2]:
        w = 0.5 * ti.sqrt(ti.max(1.0 + trace, 0.0))
        q = ti.Vector([w, (r[2, 1] - r[1, 2]) / (4.0 * w), (r[0, 2] - r[2, 0]) / (4.0 * w),
                       (r[1, 0] - r[0, 1]) / (4.0 * w)])  # fmt: skip
    elif r[0, 0] >= r[1, 1] and r[0, 0] >= r[2, 2]:
        x = 0.5 * ti.sqrt(ti.max(1.0 + r[0, 0] - r[1, 1] - r[2, 2], 0.0))
        q = ti.Vector([(r[2, 1] - r[1, 2]) / (4.0 * x), x, (r[0, 1] + r[1, 0]) / (4.0 * x),
                       (r[0, 2] + r[2, 0]) / (4.0 * x)])  # fmt: skip
    elif r[1, 1] >= r[2, 2]:
        y = 0.5 * ti.sqrt(ti.max(1.0 - r[0, 0] + r[1, 1] - r[2, 2], 0.0))
        q = ti.Vector([(r[0, 2] - r[2, 0]) / (4.0 * y), (r[0, 1] + r[1, 0]) / (4.0 * y), y,
                       (r[1, 2] + r[2, 1]) / (4.0 * y)])  # fmt: skip
    else:
        z = 0.5 * ti.sqrt(ti.max(1.0 - r[0, 0] - r[1, 1] + r[2, 2], 0.0))
        q = ti.Vector([(r[1, 0] - r[0, 1]) / (4.0 * z), (r[0, 2] + r[2, 0]) / (4.0 * z),
                       (r[1, 2] + r[2, 1]) / (4.0 * z), z])  # fmt: skip
    return q / q.norm()


@ti.func
def _rotation(q):
    """The rotation matrix of the unit quaternion ``q`` (w, x, y, z)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    return ti.Matrix([
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
        [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
        [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
    ], dt=float)  # fmt: skip


@ti.func
def _put_compact(compact: ti.template(), p, u, s, v):
    """Row p of ``compact`` (:data:`COMPACT_SVD_WIDTH` columns) from the signed SVD (U, s, V):
    returns (U, s, V) as the row gives them back (the rotations rebuilt from its quaternions),
    so that whoever reads the row later computes with the same numbers."""
    qu, qv = _quaternion(u), _quaternion(v)
    for i in ti.static(range(4)):
        compact[p, i] = qu[i]
        compact[p, 7 + i] = qv[i]
    for i in ti.static(range(3)):
        compact[p, 4 + i] = s[i]
    return _rotation(qu), s, _rotation(qv)


@ti.func
def _compact_factors(compact: ti.template(), p):
    """(U, s, V) of row p of ``compact``, as :func:`_put_compact` returned them."""
    qu = ti.Vector([compact[p, i] for i in ti.static(range(4))], dt=float)
    qv = ti.Vector([compact[p, 7 + i] for i in ti.static(range(4))], dt=float)
    s = ti.Vector([compact[p, 4 + i] for i in ti.static(range(3))], dt=float)
    return _rotation(qu), s, _rotation(qv)


@ti.func
def _diag(d):
    return ti.Matrix([[d[i] if i == j else 0.0 for j in ti.static(range(3))]
                      for i in ti.static(range(3))])  # fmt: skip


@ti.func
def _hencky_terms(s, mu, lam):
    """Per singular value: the Hencky strain eps (its floored |s|), the principal Kirchhoff
    stress t, the divisor ``safe`` (s pushed to magnitude J_FLOOR) and g = t / safe."""
    clamped = ti.max(ti.abs(s), SIGMA_FLOOR)
    eps = ti.log(clamped)
    t = 2.0 * mu * eps + lam * (eps[0] + eps[1] + eps[2])
    safe = ti.Vector([ti.max(s[i], J_FLOOR) if s[i] >= 0 else ti.min(s[i], -J_FLOOR)
                      for i in ti.static(range(3))])  # fmt: skip
    return clamped, eps, t, safe, t / safe


@ti.func
def _hencky_tau(f, u, s, v, mu, lam):
    """The StVK-Hencky Kirchhoff stress ``tau = U diag(g) V^T F^T`` of F = ``f`` from its
    signed SVD."""
    _clamped, _eps, _t, _safe, g = _hencky_terms(s, mu, lam)
    return u @ _diag(g) @ v.transpose() @ f.transpose()


@ti.kernel
def hencky_forward(
    F: ti.types.ndarray(),
    factors: ti.types.ndarray(),
    compact: ti.types.ndarray(),
    stress: ti.types.ndarray(),
    mu: float,
    lam: float,
    decompose: ti.template(),
    serial: ti.template(),
):
    """StVK-Hencky Kirchhoff stress of (B, 9) rows F, as ``bridges.laws.StVKHencky`` computes
    it, and the rows' signed SVD in the (B, 11) ``compact`` (:data:`COMPACT_SVD_WIDTH`), which
    is all the reverse needs besides F. The SVD is computed by Jacobi sweeps when
    ``decompose`` (``factors`` is then not read), else read from the (B, 21) ``factors`` (U, s,
    V); the stress is computed from the factors as ``compact`` gives them back, the numbers
    :func:`hencky_stress_again` and :func:`hencky_backward` read."""
    ti.loop_config(serialize=serial)
    for p in range(F.shape[0]):
        f = _mat(F, p, 0)
        u, s, v = ti.Matrix.zero(float, 3, 3), ti.Vector.zero(float, 3), ti.Matrix.zero(float, 3, 3)
        if ti.static(decompose):
            u, s, v = jacobi_svd(f)
        else:
            u, v = _mat(factors, p, 0), _mat(factors, p, 12)
            s = ti.Vector([factors[p, 9], factors[p, 10], factors[p, 11]], dt=float)
        u, s, v = _put_compact(compact, p, u, s, v)
        _put_mat(stress, p, 0, _hencky_tau(f, u, s, v, mu, lam))


@ti.kernel
def hencky_stress_again(F: ti.types.ndarray(), compact: ti.types.ndarray(),
                        stress: ti.types.ndarray(), mu: float, lam: float,
                        serial: ti.template()):  # fmt: skip
    """The stress :func:`hencky_forward` wrote, from the (B, 9) rows F and their (B, 11)
    ``compact`` SVD rows (no SVD computed): a step's reverse, which needs the stress, computes
    it again instead of keeping it."""
    ti.loop_config(serialize=serial)
    for p in range(F.shape[0]):
        u, s, v = _compact_factors(compact, p)
        _put_mat(stress, p, 0, _hencky_tau(_mat(F, p, 0), u, s, v, mu, lam))


@ti.kernel
def hencky_backward(
    F: ti.types.ndarray(),
    compact: ti.types.ndarray(),
    stress_grad: ti.types.ndarray(),
    F_grad: ti.types.ndarray(),
    lame_grad: ti.types.ndarray(),
    mu: float,
    lam: float,
    tol_factor: float,
    serial: ti.template(),
):
    """Reverse of :func:`hencky_forward`: (B, 9) dL/dF and each row's (dL/dmu, dL/dlam) in
    (B, 2) ``lame_grad``, from the (B, 9) dL/d tau and the (B, 11) ``compact`` SVD rows. The
    chain rule of the torch law step by step: tau = M F^T, M = U diag(g) Vh, g = t / safe, t =
    2 mu eps + lam tr(eps), eps = log(max(|s|, SIGMA_FLOOR)), and the SVD by
    :func:`_svd_adjoint`."""
    ti.loop_config(serialize=serial)
    for p in range(F.shape[0]):
        f = _mat(F, p, 0)
        u, s, v = _compact_factors(compact, p)
        clamped, eps, t, safe, g = _hencky_terms(s, mu, lam)
        vh = v.transpose()
        piola = u @ _diag(g) @ vh
        tau_grad = _mat(stress_grad, p, 0)
        piola_grad = tau_grad @ f
        f_grad = tau_grad.transpose() @ piola
        ut_piola_grad = u.transpose() @ piola_grad
        inner = ut_piola_grad @ v  # U^T dL/dM V: its diagonal is dL/dg
        g_grad = ti.Vector([inner[i, i] for i in ti.static(range(3))])
        u_grad = piola_grad @ v @ _diag(g)
        vh_grad = _diag(g) @ ut_piola_grad
        t_grad = g_grad / safe
        safe_grad = -g_grad * t / (safe * safe)
        t_sum = t_grad[0] + t_grad[1] + t_grad[2]
        eps_grad = 2.0 * mu * t_grad + lam * t_sum
        s_grad = ti.Vector.zero(float, 3)
        for i in ti.static(range(3)):
            passes = s[i] >= J_FLOOR if s[i] >= 0 else s[i] <= -J_FLOOR
            if passes:
                s_grad[i] += safe_grad[i]
            if ti.abs(s[i]) >= SIGMA_FLOOR:
                s_grad[i] += eps_grad[i] / clamped[i] * ti.math.sign(s[i])
        f_grad += _svd_adjoint(u, s, vh, u_grad, s_grad, vh_grad, tol_factor)
        _put_mat(F_grad, p, 0, f_grad)
        lame_grad[p, 0] = 2.0 * (eps[0] * t_grad[0] + eps[1] * t_grad[1] + eps[2] * t_grad[2])
        lame_grad[p, 1] = (eps[0] + eps[1] + eps[2]) * t_sum


@ti.func
def _operand(t: ti.template(), p, transposed: ti.template()):
    m = _mat(t, p, 0)
    if ti.static(transposed):
        m = m.transpose()
    return m


@ti.kernel
def product3(A: ti.types.ndarray(), B: ti.types.ndarray(), C: ti.types.ndarray(),
             transpose_a: ti.template(), transpose_b: ti.template(),
             serial: ti.template()):  # fmt: skip
    """Row p of (N, 9) ``C`` = op(A_p) op(B_p), op transposing where asked; rows of (N, 9) are
    row-major 3x3 matrices."""
    ti.loop_config(serialize=serial)
    for p in range(A.shape[0]):
        _put_mat(C, p, 0, _operand(A, p, transpose_a) @ _operand(B, p, transpose_b))


@ti.kernel
def product3_backward(A: ti.types.ndarray(), B: ti.types.ndarray(), C_grad: ti.types.ndarray(),
                      A_grad: ti.types.ndarray(), B_grad: ti.types.ndarray(),
                      transpose_a: ti.template(), transpose_b: ti.template(),
                      serial: ti.template()):  # fmt: skip
    """Reverse of C = op(A) op(B) (:func:`product3`), rows of (N, 9): dL/d op(A) =
    dL/dC op(B)^T and dL/d op(B) = op(A)^T dL/dC."""
    ti.loop_config(serialize=serial)
    for p in range(A.shape[0]):
        a, b = _operand(A, p, transpose_a), _operand(B, p, transpose_b)
        c_grad = _mat(C_grad, p, 0)
        _put_mat(A_grad, p, 0, c_grad @ b.transpose())
        _put_mat(B_grad, p, 0, a.transpose() @ c_grad)
