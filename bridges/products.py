"""Batched 3x3 matrix products in one Taichi launch, with their reverse.

``torch.bmm`` of a (N, 3, 3) batch costs about 60 ns a matrix on this CPU (one small matrix
product per matrix); a Taichi loop over the batch costs its launch, about 0.1 ms, plus a few ns
a matrix. Captured laws' ``aten.bmm`` (``F @ F.mT``, ``U @ diag(s) @ Vh``) run here
(:mod:`tasks.constitutive.law_graph`) where that pays (:func:`worthwhile`).
``python benchmarks/law_ops.py`` times both.
"""

from __future__ import annotations

import torch
from torch.autograd.function import once_differentiable

from bridges.fast_svd import runs_in_taichi, serial_loops
from taichi_mpm import runtime

#: Matrices from which one Taichi launch beats ``torch.bmm`` on one thread. With more threads
#: torch's product runs in parallel and stays ahead: ``benchmarks/law_ops.py`` on 10,000
#: matrices, forward and backward, measured 1365 against 2139 us on one thread but 993 against
#: 941 us on two.
MIN_BATCH = 4096


def worthwhile(A: torch.Tensor) -> bool:
    """Whether :func:`bmm3` is faster than ``torch.bmm`` for the batch ``A`` here: from
    ``MIN_BATCH`` matrices, with a Taichi runtime of one CPU thread."""
    try:
        info = runtime.current()
    except runtime.RuntimeNotInitialized:
        return False
    return A.dim() == 3 and A.shape[0] >= MIN_BATCH and info.arch == "cpu" and info.threads == 1


def _rows(t: torch.Tensor) -> tuple[torch.Tensor, bool]:
    """(N, 9) rows of a (N, 3, 3) batch and whether they hold its transposes: a transposed view
    (``F.mT``) is read as it lies, since copying it costs as much as the product."""
    t = t.detach()
    if not t.is_contiguous() and t.mT.is_contiguous():
        return t.mT.reshape(-1, 9), True
    return t.reshape(-1, 9).contiguous(), False


class _Product3(torch.autograd.Function):
    @staticmethod
    def forward(ctx, A: torch.Tensor, B: torch.Tensor) -> torch.Tensor:
        from bridges import kernels  # compiles on first use only

        (a, transpose_a), (b, transpose_b) = _rows(A), _rows(B)
        product = torch.empty_like(a)
        kernels.product3(a, b, product, transpose_a, transpose_b, serial_loops(a))
        # the inputs, not their rows: a row copy of a strided input (a slice of an SVD's
        # factors, say) would be a tensor of its own in the graph, the input is kept anyway
        ctx.save_for_backward(A, B)
        return product.reshape(A.shape)

    @staticmethod
    @once_differentiable
    def backward(ctx, C_grad: torch.Tensor):
        from bridges import kernels

        A, B = ctx.saved_tensors
        (a, transpose_a), (b, transpose_b) = _rows(A), _rows(B)
        c_grad, _ = _rows(C_grad.contiguous())
        shape, serial = C_grad.shape, serial_loops(a)
        wants_a, wants_b = ctx.needs_input_grad
        if wants_a and wants_b:
            A_grad, B_grad = torch.empty_like(a), torch.empty_like(b)
            kernels.product3_backward(a, b, c_grad, A_grad, B_grad, transpose_a, transpose_b,
                                      serial)  # fmt: skip
            return A_grad.reshape(shape), B_grad.reshape(shape)
        if wants_a:  # dL/dA = dL/dC op(B)^T
            A_grad = torch.empty_like(a)
            kernels.product3(c_grad, b, A_grad, False, not transpose_b, serial)
            return A_grad.reshape(shape), None
        B_grad = torch.empty_like(b)  # dL/dB = op(A)^T dL/dC
        kernels.product3(a, c_grad, B_grad, not transpose_a, False, serial)
        return None, B_grad.reshape(shape)


def bmm3(A: torch.Tensor, B: torch.Tensor) -> torch.Tensor | None:
    """``torch.bmm(A, B)`` of two (N, 3, 3) batches in Taichi, or None where that does not
    apply (other shapes, dtypes or devices, no Taichi CPU runtime of their precision)."""
    if A.dim() != 3 or A.shape != B.shape or A.dtype != B.dtype or A.device != B.device:
        return None
    if not runs_in_taichi(A, ("float32", "float64")):
        return None
    return _Product3.apply(A, B)


class _ScaledProduct(torch.autograd.Function):
    @staticmethod
    def forward(ctx, A: torch.Tensor, d: torch.Tensor, B: torch.Tensor) -> torch.Tensor:
        ctx.save_for_backward(A, d, B)
        return torch.bmm(A * d.unsqueeze(-2), B)

    @staticmethod
    @once_differentiable
    def backward(ctx, C_grad: torch.Tensor):
        A, d, B = ctx.saved_tensors
        wants_a, wants_d, wants_b = ctx.needs_input_grad
        A_grad = d_grad = B_grad = None
        if wants_a or wants_d:
            grad_times_bt = torch.bmm(C_grad, B.mT)  # dL/d(A diag(d))
            if wants_a:
                A_grad = grad_times_bt * d.unsqueeze(-2)
            if wants_d:
                d_grad = (A * grad_times_bt).sum(-2)
        if wants_b:
            B_grad = torch.bmm((A * d.unsqueeze(-2)).mT, C_grad)
        return A_grad, d_grad, B_grad


def scaled_product(A: torch.Tensor, d: torch.Tensor, B: torch.Tensor) -> torch.Tensor:
    """``A @ diag_embed(d) @ B`` of (N, n, n) ``A``, ``B`` and (N, n) ``d`` (a law's way back
    from singular values: ``U @ diag(s) @ Vh``), keeping only its inputs for the reverse: in a
    law they are an SVD's factors and the new singular values, which the graph keeps anyway,
    where autograd's product of ``A * d`` with ``B`` would also keep the scaled A."""
    return _ScaledProduct.apply(A, d, B)


def compile_kernels(dtype: torch.dtype) -> None:
    """Launch the product kernels once in each orientation a captured law's products take
    (``A @ B``, ``A @ B^T``, ``A^T @ B``), forward and backward, if :func:`worthwhile` sends
    batches of ``dtype`` there, so that the first law that uses them does not wait for them to
    compile (a fit worker's warm-up)."""
    A = torch.eye(3, dtype=dtype).expand(MIN_BATCH, 3, 3).contiguous()
    if not worthwhile(A) or not runs_in_taichi(A, ("float32", "float64")):
        return
    for transpose_a, transpose_b in ((False, False), (False, True), (True, False)):
        left, right = A.clone().requires_grad_(), A.clone().requires_grad_()
        product = bmm3(left.mT if transpose_a else left, right.mT if transpose_b else right)
        product.sum().backward()
