"""Differentiable isotropic matrix functions built on a non-differentiable SVD.

``ti.svd`` has no usable gradient. The SVD F = U diag(S) V^T is therefore computed in a
forward-only kernel and stored, with the coefficients below, in arrays without
gradients, so the differentiated kernels see them as constants. From them
:func:`isotropic_uv` builds an expression whose *value* is G(F) = U diag(g(S)) V^T and
whose *first derivative* in F is the exact derivative of that isotropic function:

* the diagonal of K = U^T F V carries dS (first-order perturbation theory), and the
  law g is differentiated by Taichi's autodiff through it;
* the off-diagonal entries of K carry the rotation of U and V; for each pair (i, j)
  dG'_ij = a K_ij + b K_ji and dG'_ji = a K_ji + b K_ij with
  a = (D + P) / 2, b = (D - P) / 2, D = (g_j - g_i) / (S_j - S_i), P = (g_j + g_i) / (S_j + S_i).

D is evaluated at singular values spread apart to at least ``tol``, which gives its
limit (no division by zero) for repeated singular values, e.g. an undeformed body.
Reverse mode needs first derivatives only, so gradients through these expressions are
exact up to O(tol) at near-repeated singular values. Keeping the coefficients out of the
differentiated kernels also keeps their compile time short.
"""

import taichi as ti

from taichi_mpm.kernels.linalg import matmul, matmul_t, t_matmul

PAIRS = ((0, 1), (0, 2), (1, 2))


@ti.func
def signed_floor(value, floor):
    """value pushed away from zero to magnitude >= floor, keeping its sign."""
    return ti.select(value >= 0, ti.max(value, floor), ti.min(value, -floor))


@ti.func
def singular_values(F):
    """Signed SVD F = U diag(S) V^T (det U = det V = 1)."""
    U, S, V = ti.svd(F)
    return U, ti.Vector([S[0, 0], S[1, 1], S[2, 2]]), V


@ti.func
def pair_coefficients(S, law: ti.template(), prm, tol):
    """(a, b) of every singular-value pair, as a 3x2 matrix (rows follow PAIRS)."""
    g = law(S, prm)
    coefficients = ti.Matrix.zero(float, 3, 2)
    for row in ti.static(range(3)):
        i, j = PAIRS[row]
        gap = S[j] - S[i]
        D = 0.0
        if ti.abs(gap) >= tol:
            D = (g[j] - g[i]) / gap
        else:
            gap = signed_floor(gap, tol)
            mid = 0.5 * (S[i] + S[j])
            spread = S
            spread[i] = mid - 0.5 * gap
            spread[j] = mid + 0.5 * gap
            g_spread = law(spread, prm)
            D = (g_spread[j] - g_spread[i]) / gap
        P = (g[j] + g[i]) / signed_floor(S[j] + S[i], tol)
        coefficients[row, 0] = 0.5 * (D + P)
        coefficients[row, 1] = 0.5 * (D - P)
    return coefficients


@ti.func
def isotropic_uv(F, U, V, coefficients, law: ti.template(), prm):
    """G(F) = U diag(law(S)) V^T with the exact first derivative in F."""
    K = matmul(t_matmul(U, F), V)
    g = law(ti.Vector([K[0, 0], K[1, 1], K[2, 2]]), prm)
    a01, b01 = coefficients[0, 0], coefficients[0, 1]
    a02, b02 = coefficients[1, 0], coefficients[1, 1]
    a12, b12 = coefficients[2, 0], coefficients[2, 1]
    X = ti.Matrix(
        [
            [g[0], a01 * K[0, 1] + b01 * K[1, 0], a02 * K[0, 2] + b02 * K[2, 0]],
            [a01 * K[1, 0] + b01 * K[0, 1], g[1], a12 * K[1, 2] + b12 * K[2, 1]],
            [a02 * K[2, 0] + b02 * K[0, 2], a12 * K[2, 1] + b12 * K[1, 2], g[2]],
        ]
    )
    return matmul_t(matmul(U, X), V)
