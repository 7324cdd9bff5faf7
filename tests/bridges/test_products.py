"""Batched 3x3 products in Taichi equal ``torch.bmm``, values and gradients (float64)."""

import os
import subprocess
import sys

import pytest
import torch

from bridges.products import MIN_BATCH, bmm3, scaled_product, worthwhile
from taichi_mpm import runtime


def _batches(count: int, seed: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    generator = torch.Generator().manual_seed(seed)
    return tuple(torch.randn(count, 3, 3, dtype=torch.float64, generator=generator)
                 for _ in range(3))  # fmt: skip


@pytest.mark.parametrize("needs", [(True, True), (True, False), (False, True)])
def test_products_and_their_gradients_equal_bmm(needs):
    A, B, weights = _batches(500, seed=sum(needs))
    results = []
    for product in (bmm3, torch.bmm):
        a, b = A.clone().requires_grad_(needs[0]), B.clone().requires_grad_(needs[1])
        # transposed views (read without a copy) on either side
        out = product(a.mT if needs[1] else a, b.mT if needs[0] else b)
        (weights * out).sum().backward()
        results.append([out.detach(), a.grad, b.grad])
    for got, expected in zip(*results, strict=True):
        if expected is None:
            assert got is None
        else:
            torch.testing.assert_close(got, expected, rtol=1e-13, atol=1e-13)


def test_products_match_finite_differences():
    A, B, _ = _batches(6, seed=5)
    inputs = (A.requires_grad_(True), B.requires_grad_(True))
    assert torch.autograd.gradcheck(bmm3, inputs)


def test_a_scaled_product_equals_the_products_and_matches_finite_differences():
    """``A diag(d) B`` in one operation: the values and gradients of ``A @ diag_embed(d) @ B``,
    finite differences, and only the inputs kept for the reverse."""
    A, B, weights = _batches(50, seed=7)
    d = torch.rand(50, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(8)) + 0.1
    results = []
    for product in (scaled_product, lambda a, s, b: a @ torch.diag_embed(s) @ b):
        inputs = [t.clone().requires_grad_() for t in (A, d, B)]
        (weights * product(*inputs)).sum().backward()
        results.append([product(*inputs).detach(), *(t.grad for t in inputs)])
    for got, expected in zip(*results, strict=True):
        torch.testing.assert_close(got, expected, rtol=1e-12, atol=1e-12)
    inputs = tuple(t[:5].clone().requires_grad_() for t in (A, d, B))
    assert torch.autograd.gradcheck(scaled_product, inputs)
    node = scaled_product(*inputs).grad_fn
    assert {t.data_ptr() for t in node.saved_tensors} == {t.data_ptr() for t in inputs}


def test_other_shapes_dtypes_and_precisions_are_left_to_torch():
    A, B, _ = _batches(4, seed=6)
    assert bmm3(A, B[:3]) is None  # batch sizes differ
    assert bmm3(A[0], B[0]) is None  # not a batch
    assert bmm3(A, B.float()) is None  # dtypes differ
    assert bmm3(A.float(), B.float()) is None  # the session's runtime is float64
    assert (
        bmm3(torch.randn(4, 2, 2, dtype=torch.float64), torch.randn(4, 2, 2, dtype=torch.float64))
        is None
    )


def test_taichi_takes_the_product_only_where_it_is_faster():
    """One launch beats torch.bmm from MIN_BATCH matrices, on one thread only."""
    one_thread = runtime.current().threads == 1
    assert not worthwhile(torch.zeros(MIN_BATCH - 1, 3, 3, dtype=torch.float64))
    assert worthwhile(torch.zeros(MIN_BATCH, 3, 3, dtype=torch.float64)) == one_thread


ONE_THREAD = """
import torch
import taichi_mpm
from bridges import products
from taichi_mpm import _compat

taichi_mpm.init(arch="cpu", precision="float32")
products.compile_kernels(torch.float32)
compiled = []
_compat.on_compile(compiled.append)
F = torch.randn(products.MIN_BATCH, 3, 3, requires_grad=True)
s = torch.rand(products.MIN_BATCH, 3)
U, V = torch.linalg.qr(torch.randn(2, products.MIN_BATCH, 3, 3)).Q
Vh = V.mT
first = products.bmm3(F, F.mT)  # F F^T
second = products.bmm3(products.bmm3(U, torch.diag_embed(s).requires_grad_()), Vh)
(first.sum() + second.sum()).backward()
print(compiled)
"""


def test_compile_kernels_leaves_a_laws_products_nothing_to_compile():
    """In a one-thread float32 runtime (where products run in Taichi), after the warm-up the
    products of ``F @ F.mT`` and ``U @ diag(s) @ Vh`` and their reverse compile nothing."""
    env = {**os.environ, "TI_CPU_MAX_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, "-c", ONE_THREAD], capture_output=True, text=True,
                         check=True, env=env)  # fmt: skip
    assert out.stdout.strip().splitlines()[-1] == "[]"
