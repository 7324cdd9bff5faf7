"""SVD of one 3x3 matrix by Jacobi rotations: faster than ``ti.svd`` and as accurate in float32.

``A^T A`` is diagonalised by up to four cyclic sweeps of Jacobi rotations (three rotations a
sweep, each zeroing one off-diagonal entry exactly, accumulated into V), stopping once the
off-diagonal entries are below float32 round-off of the diagonal (``CONVERGED``). The columns
of ``B = A V`` are then orthogonal; sorted by decreasing norm, their Gram-Schmidt
orthonormalisation gives U with ``B = U R``, R upper triangular with negligible off-diagonal,
so ``A = U diag(R) V^T``. The third column of U is the cross product of the first two, so
det U = +1; column swaps negate one column, so det V stays +1; the sign of det A lands on the
last singular value (the MPM convention of ``ti.svd``).

Accuracy (float32, against LAPACK in float64): reconstruction and orthogonality ~1e-6 for
deformation gradients near the identity, general and rank-deficient matrices and repeated
singular values, like ``ti.svd`` or better. Squaring A costs relative accuracy in the smallest
singular value only when it is tiny next to the largest (ill-conditioned A). Checked in
``tests/bridges/test_fast_svd.py``; timed by ``benchmarks/svd3.py``.
"""

import taichi as ti

#: Cyclic sweeps over the three off-diagonal pairs at most: three already reach float32
#: round-off near the identity, four also for general matrices.
SWEEPS = 4
#: Squared off-diagonal norm of A^T A, relative to its squared diagonal, below which no further
#: sweep runs (1e-8 relative: under float32 round-off).
CONVERGED = 1e-16
_TINY = 1e-30


@ti.func
def _rotate(S, V, p: ti.template(), q: ti.template()):
    """One Jacobi rotation in the (p, q) plane zeroing S[p, q] of symmetric S; V <- V G."""
    r = ti.static(3 - p - q)
    s_pq = S[p, q]
    if ti.abs(s_pq) > _TINY:
        theta = (S[q, q] - S[p, p]) / (2.0 * s_pq)
        t = 1.0 / (ti.abs(theta) + ti.sqrt(theta * theta + 1.0))  # the smaller root
        if theta < 0:
            t = -t
        c = 1.0 / ti.sqrt(t * t + 1.0)
        s = t * c
        s_rp, s_rq = S[r, p], S[r, q]
        S[p, p] -= t * s_pq
        S[q, q] += t * s_pq
        S[p, q] = 0.0
        S[q, p] = 0.0
        S[r, p] = c * s_rp - s * s_rq
        S[p, r] = S[r, p]
        S[r, q] = s * s_rp + c * s_rq
        S[q, r] = S[r, q]
        for i in ti.static(range(3)):
            v_p, v_q = V[i, p], V[i, q]
            V[i, p] = c * v_p - s * v_q
            V[i, q] = s * v_p + c * v_q
    return S, V


@ti.func
def _swap_columns(B, V, a: ti.template(), b: ti.template()):
    """Columns a and b of B and V exchanged, one negated (keeps det V)."""
    for i in ti.static(range(3)):
        B[i, a], B[i, b] = B[i, b], -B[i, a]
        V[i, a], V[i, b] = V[i, b], -V[i, a]
    return B, V


@ti.func
def _column(M, j: ti.template()):
    return ti.Vector([M[0, j], M[1, j], M[2, j]])


@ti.func
def jacobi_svd(A):
    """``U, s, V`` with ``A = U diag(s) V^T``: U and V rotations, ``|s|`` descending, s[2]
    negative when det A < 0."""
    S = A.transpose() @ A
    V = ti.Matrix.identity(float, 3)
    diagonal = S[0, 0] * S[0, 0] + S[1, 1] * S[1, 1] + S[2, 2] * S[2, 2]
    for _ in range(SWEEPS):
        if S[0, 1] * S[0, 1] + S[0, 2] * S[0, 2] + S[1, 2] * S[1, 2] <= CONVERGED * diagonal:
            break
        S, V = _rotate(S, V, 0, 1)
        S, V = _rotate(S, V, 0, 2)
        S, V = _rotate(S, V, 1, 2)
    B = A @ V
    norms = ti.Vector([_column(B, j).norm_sqr() for j in ti.static(range(3))])
    if norms[0] < norms[1]:
        B, V = _swap_columns(B, V, 0, 1)
        norms[0], norms[1] = norms[1], norms[0]
    if norms[0] < norms[2]:
        B, V = _swap_columns(B, V, 0, 2)
        norms[0], norms[2] = norms[2], norms[0]
    if norms[1] < norms[2]:
        B, V = _swap_columns(B, V, 1, 2)
    b0, b1 = _column(B, 0), _column(B, 1)
    s0 = ti.sqrt(norms[0])
    u0 = ti.Vector([1.0, 0.0, 0.0])
    if s0 > _TINY:
        u0 = b0 / s0
    rest = b1 - u0.dot(b1) * u0
    s1 = rest.norm()
    u1 = ti.Vector([0.0, 1.0, 0.0])
    if s1 > 1e-6 * s0 + _TINY:
        u1 = rest / s1
    else:  # rank <= 1: any unit vector orthogonal to u0
        axis = ti.Vector([1.0, 0.0, 0.0]) if ti.abs(u0[0]) < 0.9 else ti.Vector([0.0, 1.0, 0.0])
        u1 = (axis - u0.dot(axis) * u0).normalized()
        s1 = u1.dot(b1)
    u2 = u0.cross(u1)
    U = ti.Matrix.cols([u0, u1, u2])
    return U, ti.Vector([s0, s1, u2.dot(_column(B, 2))]), V
