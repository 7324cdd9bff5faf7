"""Small 3x3 linear algebra written as pure expressions.

Taichi's own ``@`` and ``outer_product`` accumulate into mutable local matrices; its
reverse-mode pass then takes tens of seconds to compile a kernel (15 s for two matrix
products, measured with Taichi 1.7.4). The same products written as expressions
compile in well under a second, so every differentiated kernel uses these.
"""

import taichi as ti


@ti.func
def matmul(A, B):
    """A @ B for 3x3 matrices."""
    return ti.Matrix(
        [
            [A[i, 0] * B[0, j] + A[i, 1] * B[1, j] + A[i, 2] * B[2, j] for j in ti.static(range(3))]
            for i in ti.static(range(3))
        ]
    )


@ti.func
def matmul_t(A, B):
    """A @ B^T for 3x3 matrices."""
    return ti.Matrix(
        [
            [A[i, 0] * B[j, 0] + A[i, 1] * B[j, 1] + A[i, 2] * B[j, 2] for j in ti.static(range(3))]
            for i in ti.static(range(3))
        ]
    )


@ti.func
def t_matmul(A, B):
    """A^T @ B for 3x3 matrices."""
    return ti.Matrix(
        [
            [A[0, i] * B[0, j] + A[1, i] * B[1, j] + A[2, i] * B[2, j] for j in ti.static(range(3))]
            for i in ti.static(range(3))
        ]
    )


@ti.func
def matvec(A, b):
    """A @ b for a 3x3 matrix and a 3-vector."""
    return ti.Vector(
        [A[i, 0] * b[0] + A[i, 1] * b[1] + A[i, 2] * b[2] for i in ti.static(range(3))]
    )


@ti.func
def t_matvec(A, b):
    """A^T @ b for a 3x3 matrix and a 3-vector."""
    return ti.Vector(
        [A[0, i] * b[0] + A[1, i] * b[1] + A[2, i] * b[2] for i in ti.static(range(3))]
    )


@ti.func
def outer(a, b):
    """a b^T for 3-vectors."""
    return ti.Matrix([[a[i] * b[j] for j in ti.static(range(3))] for i in ti.static(range(3))])


@ti.func
def det(A):
    """Determinant of a 3x3 matrix."""
    return (
        A[0, 0] * (A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1])
        - A[0, 1] * (A[1, 0] * A[2, 2] - A[1, 2] * A[2, 0])
        + A[0, 2] * (A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0])
    )


@ti.func
def trace(A):
    return A[0, 0] + A[1, 1] + A[2, 2]


@ti.func
def identity():
    return ti.Matrix([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


@ti.func
def sum_terms(terms: ti.template(), lo: ti.template(), hi: ti.template()):
    """terms[lo] + ... + terms[hi - 1] of a compile-time list, as a balanced tree of additions.

    Accumulating into a local variable instead makes the reverse-mode kernel ~3x slower.
    """
    if ti.static(hi - lo == 1):
        return terms[lo]
    else:
        return sum_terms(terms, lo, (lo + hi) // 2) + sum_terms(terms, (lo + hi) // 2, hi)
