"""Batched 3x3 SVD in Taichi kernels: values by Jacobi rotations (float32), and the backward.

torch runs a LAPACK call per 3x3 matrix (~1.7 us each on this CPU); the kernel runs
:func:`taichi_mpm.kernels.jacobi_svd.jacobi_svd` over the whole batch in one launch
(``benchmarks/svd3.py``). Its float32 result is as accurate as float32 allows
(reconstruction ~1e-6); float64 stays with torch, whose LAPACK reaches 1e-15.
Used for the values of :func:`bridges.linalg.svd` when a float32 Taichi CPU runtime is running;
otherwise the caller falls back to torch.

The backward of :func:`bridges.linalg.svd` (its clamped formula) is one Taichi pass per matrix
wherever a Taichi CPU runtime of the tensors' precision runs: torch spends ~25 small batched
operations on it.
"""

from __future__ import annotations

import torch

from taichi_mpm import runtime

_PRECISIONS = {torch.float32: "float32", torch.float64: "float64"}


def runs_in_taichi(tensor: torch.Tensor, precisions: tuple[str, ...]) -> bool:
    """A non-empty CPU batch of 3x3 matrices, in a precision of ``precisions`` that a Taichi CPU
    runtime runs in."""
    if tensor.device.type != "cpu" or tensor.ndim < 2 or tensor.shape[-2:] != (3, 3):
        return False
    if tensor.numel() == 0 or _PRECISIONS.get(tensor.dtype) not in precisions:
        return False
    try:
        info = runtime.current()
    except runtime.RuntimeNotInitialized:
        return False
    return info.arch == "cpu" and info.precision == _PRECISIONS[tensor.dtype]


def serial_loops(rows: torch.Tensor) -> bool:
    """Whether a kernel over the rows of ``rows`` should loop serially here
    (:func:`taichi_mpm.runtime.parallel_worthwhile`)."""
    return not runtime.parallel_worthwhile(rows.shape[0])


def taichi_svd(F: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor] | None:
    """Signed (det U = det V = +1) SVD ``(U, S, Vh)`` of (..., 3, 3) ``F``, or None.

    None unless ``F`` is a non-empty float32 batch of 3x3 matrices on the CPU and a float32
    Taichi CPU runtime is running. Singular values come sorted by decreasing magnitude.
    """
    if not runs_in_taichi(F, ("float32",)):
        return None
    from bridges import kernels  # compiles on first use only

    flat = F.detach().reshape(-1, 9).contiguous()
    out = flat.new_empty(flat.shape[0], 21)  # U, S, V per row
    kernels.svd3(flat, out, serial_loops(flat))
    batch = F.shape[:-2]
    U = out[:, :9].reshape(*batch, 3, 3)
    V = out[:, 12:].reshape(*batch, 3, 3)
    return U, out[:, 9:12].reshape(*batch, 3), V.mT


def taichi_svd_backward(
    U: torch.Tensor,
    S: torch.Tensor,
    Vh: torch.Tensor,
    grads: tuple[torch.Tensor | None, torch.Tensor | None, torch.Tensor | None],
    tol_factor: float,
) -> torch.Tensor | None:
    """dL/dF of ``F = U diag(S) Vh`` from ``grads`` = (dL/dU, dL/dS, dL/dVh), any of them None
    (zero), with the clamp of :mod:`bridges.linalg`; None where Taichi does not apply."""
    if not runs_in_taichi(U, ("float32", "float64")):
        return None
    from bridges import kernels

    batch = U.shape[:-2]

    def rows(tensor: torch.Tensor | None, like: torch.Tensor, width: int) -> torch.Tensor:
        if tensor is None:
            return like.new_zeros(like[..., 0, 0].numel(), width)
        return tensor.reshape(-1, width).contiguous()

    F_grad = U.new_empty(U[..., 0, 0].numel(), 9)
    kernels.svd3_backward(
        rows(U, U, 9), rows(S, U, 3), rows(Vh, U, 9),
        rows(grads[0], U, 9), rows(grads[1], U, 3), rows(grads[2], U, 9),
        F_grad, tol_factor, serial_loops(F_grad),
    )  # fmt: skip
    return F_grad.reshape(*batch, 3, 3)
