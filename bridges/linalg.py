"""Batched 3x3 linear algebra with gradients that stay finite at repeated singular values.

Constitutive laws take the SVD of deformation gradients near the identity, where singular
values coincide. ``torch.linalg.svd`` then returns NaN or inf gradients, because its
backward divides by ``s_j^2 - s_i^2``. :func:`svd` computes the same decomposition with a
backward whose singular factors are clamped; :func:`polar` and :func:`trace` build on it.

While :func:`stable_linalg` is active, ``torch.linalg.svd``, ``torch.svd`` and
``torch.Tensor.svd`` route (..., 3, 3) real inputs to the stable backward, keeping their
usual values (non-negative, descending singular values). Constitutive laws run by the
bridge are evaluated inside it, so laws written with plain torch calls (LLM-written ones
included) get finite gradients without changes. Code that bound the functions before
entering (``from torch.linalg import svd``) keeps the originals.

Gradient clamp
--------------
For i != j the backward needs ``(a s_j + b s_i) / (s_j^2 - s_i^2)``, with ``a = J - J^T``,
``b = K - K^T``, ``J = U^T dL/dU`` and ``K = V^T dL/dV``. It is evaluated in the equivalent form
``(a + b) / (2 (s_j - s_i)) + (a - b) / (2 (s_j + s_i))``, each denominator's magnitude
clamped to ``tol = sqrt(machine epsilon) * max(1, max_k |s_k|)`` with its sign kept
(1.5e-8 in float64, 3.5e-4 in float32, for O(1) singular values). For gaps above ``tol``
the formula is the exact gradient; roundoff in its numerators costs a relative error of
about ``machine epsilon / gap`` (1e-12 for a gap of 1e-4 in float64), and the square root
balances that error against the bias for gaps below ``tol``, where ``a + b`` is divided by
``tol`` instead of the gap. At exactly repeated singular values the gradient stays
finite: the ``a - b`` part (e.g. the whole derivative of the polar rotation at F = c I) is
still exact, while ``a + b`` vanishes for an isotropic function and is divided by ``tol``,
so the derivative of U diag(g(S)) V^T loses its (g_j - g_i) / (s_j - s_i) limit there.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator

import torch
from torch.autograd.function import once_differentiable

from bridges.fast_svd import taichi_svd, taichi_svd_backward

__all__ = ["polar", "real_3x3", "stable_linalg", "svd", "trace"]

_linalg_svd = torch.linalg.svd
_torch_svd = torch.svd
_tensor_svd_own = torch.Tensor.__dict__.get("svd")  # None: inherited from the C base class
_tensor_svd = torch.Tensor.svd


def _clamp_magnitude(x: torch.Tensor, tol: torch.Tensor) -> torch.Tensor:
    """x with its magnitude raised to at least tol, keeping its sign (0 counts as positive)."""
    return torch.where(x >= 0, torch.maximum(x, tol), torch.minimum(x, -tol))


class _SVD(torch.autograd.Function):
    """F = U diag(S) Vh with the clamped backward described in the module docstring."""

    @staticmethod
    def forward(ctx, F: torch.Tensor, signed: bool) -> tuple[torch.Tensor, ...]:
        U, S, Vh = _decompose(F, signed)
        ctx.set_materialize_grads(False)
        ctx.save_for_backward(U, S, Vh)
        return U, S, Vh

    @staticmethod
    @once_differentiable
    def backward(ctx, gU, gS, gVh):
        U, S, Vh = ctx.saved_tensors
        tol_factor = torch.finfo(S.dtype).eps ** 0.5
        fast = taichi_svd_backward(U, S, Vh, (gU, gS, gVh), tol_factor)
        return (fast if fast is not None else svd_backward(U, S, Vh, gU, gS, gVh)), None


def svd_backward(U, S, Vh, gU, gS, gVh) -> torch.Tensor:
    """dL/dF of F = U diag(S) Vh in torch, clamped as the module docstring says (any of the
    incoming gradients may be None)."""
    inner = torch.zeros_like(U)
    if gU is not None or gVh is not None:
        a = U.mT @ gU if gU is not None else torch.zeros_like(U)
        b = Vh @ gVh.mT if gVh is not None else torch.zeros_like(U)
        a, b = a - a.mT, b - b.mT
        s_i, s_j = S[..., :, None], S[..., None, :]
        tol = torch.finfo(S.dtype).eps ** 0.5 * S.abs().amax(-1).clamp(min=1.0)
        tol = tol[..., None, None]
        inner = (a + b) / (2 * _clamp_magnitude(s_j - s_i, tol)) + (a - b) / (
            2 * _clamp_magnitude(s_j + s_i, tol)
        )
    if gS is not None:
        inner = inner + torch.diag_embed(gS)
    return U @ inner @ Vh


def _decompose(F: torch.Tensor, signed: bool) -> tuple[torch.Tensor, ...]:
    """Values of the SVD: Taichi's batched 3x3 SVD where it applies, else torch's."""
    fast = taichi_svd(F)
    if fast is not None:
        U, S, Vh = fast
        if signed:
            return U, S, Vh
        flip = S[..., 2] < 0  # torch's convention: S >= 0, U may be a reflection
        U[..., :, 2] = torch.where(flip[..., None], -U[..., :, 2], U[..., :, 2])
        S[..., 2] = S[..., 2].abs()
        return U, S, Vh
    U, S, Vh = _linalg_svd(F)
    if signed:
        flip_u = torch.linalg.det(U) < 0
        flip_v = torch.linalg.det(Vh) < 0
        U = U.clone()
        Vh = Vh.clone()
        S = S.clone()
        U[..., :, 2] = torch.where(flip_u[..., None], -U[..., :, 2], U[..., :, 2])
        Vh[..., 2, :] = torch.where(flip_v[..., None], -Vh[..., 2, :], Vh[..., 2, :])
        S[..., 2] = torch.where(flip_u ^ flip_v, -S[..., 2], S[..., 2])
    return U, S, Vh


def svd(F: torch.Tensor, signed: bool = True) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """SVD of (..., 3, 3) matrices with finite gradients at repeated singular values.

    Parameters
    ----------
    F : torch.Tensor
        Real matrices, shape (..., 3, 3).
    signed : bool
        MPM convention (default): det U = det V = +1, and the last (smallest) singular
        value carries the sign of det F, so ``S[..., 2]`` is negative for inverted F.
        ``False`` gives torch's convention (S >= 0, U and V possibly reflections).

    Returns
    -------
    U, S, Vh : torch.Tensor
        ``F = U @ diag(S) @ Vh``, S in descending order of magnitude.
    """
    return _SVD.apply(F, signed)


def polar(F: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Polar decomposition F = R S of (..., 3, 3) matrices, built on the signed :func:`svd`.

    Returns
    -------
    R, S : torch.Tensor
        R a rotation (det R = +1), S symmetric; S is positive definite when det F > 0 and
        has one negative eigenvalue when det F < 0.
    """
    U, sigma, Vh = svd(F)
    return U @ Vh, Vh.mT @ (sigma[..., :, None] * Vh)


def trace(A: torch.Tensor) -> torch.Tensor:
    """Trace of (..., n, n) matrices, shape (...)."""
    return A.diagonal(dim1=-2, dim2=-1).sum(-1)


# ------------------------------------------------------------------- routing torch's SVDs


def real_3x3(A: object) -> bool:
    """Whether ``A`` is a real floating-point tensor of (..., 3, 3) matrices: what the routed
    SVDs and the closed forms of :mod:`bridges.closed_form` take."""
    return (
        isinstance(A, torch.Tensor)
        and A.dim() >= 2
        and A.shape[-2:] == (3, 3)
        and A.dtype.is_floating_point
    )


def _stable_linalg_svd(A, full_matrices=True, *, driver=None, out=None):
    if driver is not None or out is not None or not real_3x3(A):
        return _linalg_svd(A, full_matrices, driver=driver, out=out)
    return torch.return_types.linalg_svd(svd(A, signed=False))


def _stable_torch_svd(input, some=True, compute_uv=True, *, out=None):
    if not compute_uv or out is not None or not real_3x3(input):
        return _torch_svd(input, some, compute_uv, out=out)
    U, S, Vh = svd(input, signed=False)
    return torch.return_types.svd((U, S, Vh.mT))


def _stable_tensor_svd(self, some=True, compute_uv=True):
    if not compute_uv or not real_3x3(self):
        return _tensor_svd(self, some, compute_uv)
    return _stable_torch_svd(self)


_lock = threading.Lock()
_depth = 0


def _install() -> None:
    torch.linalg.svd = _stable_linalg_svd
    torch.svd = _stable_torch_svd
    torch.Tensor.svd = _stable_tensor_svd


def _uninstall() -> None:
    torch.linalg.svd = _linalg_svd
    torch.svd = _torch_svd
    if _tensor_svd_own is None:
        del torch.Tensor.svd
    else:
        torch.Tensor.svd = _tensor_svd_own


@contextlib.contextmanager
def stable_linalg() -> Iterator[None]:
    """Route torch's 3x3 SVDs to the stable backward while active.

    Re-entrant (nested uses keep the routing until the outermost exits) and restores the
    original functions on exit, also when the block raises. The routing is process-wide:
    other threads see it while any block is active.
    """
    global _depth
    with _lock:
        if _depth == 0:
            _install()
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0:
                _uninstall()
