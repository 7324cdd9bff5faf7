"""The closed-form 3x3 determinant and inverse against torch's LU-based ones."""

import pytest
import torch

from bridges.closed_form import det3, inv3, inverse_and_det
from bridges.linalg import real_3x3


def matrices(batch: int = 32, spread: float = 0.3, seed: int = 0) -> torch.Tensor:
    generator = torch.Generator().manual_seed(seed)
    noise = torch.randn(batch, 3, 3, generator=generator, dtype=torch.float64)
    return torch.eye(3, dtype=torch.float64) + spread * noise


def test_determinant_matches_lu_and_has_exact_gradients():
    A = matrices()
    assert torch.allclose(det3(A), torch.linalg.det(A), rtol=1e-13, atol=1e-15)
    assert torch.autograd.gradcheck(det3, (A[:4].clone().requires_grad_(),))
    A.requires_grad_(True)
    (found,) = torch.autograd.grad(det3(A).square().sum(), A)
    (expected,) = torch.autograd.grad(torch.linalg.det(A).square().sum(), A)
    assert torch.allclose(found, expected, rtol=1e-12, atol=1e-14)


def test_inverse_matches_lu_and_has_exact_gradients():
    A = matrices(spread=1.0, seed=1)  # general matrices, not only near the identity
    assert torch.allclose(inv3(A) @ A, torch.eye(3, dtype=A.dtype).expand_as(A), atol=1e-11)
    assert torch.allclose(inv3(A), torch.linalg.inv(A), rtol=1e-10, atol=1e-12)
    inverse, det = inverse_and_det(A)
    assert torch.equal(inverse, inv3(A)) and torch.equal(det, det3(A))
    assert torch.autograd.gradcheck(inv3, (A[:4].clone().requires_grad_(),))
    A.requires_grad_(True)
    weights = torch.randn(A.shape, dtype=A.dtype, generator=torch.Generator().manual_seed(2))
    (found,) = torch.autograd.grad((weights * inv3(A)).sum(), A)
    (expected,) = torch.autograd.grad((weights * torch.linalg.inv(A)).sum(), A)
    assert torch.allclose(found, expected, rtol=1e-9, atol=1e-11)


def test_shapes_and_where_the_closed_forms_apply():
    A = matrices(batch=6).reshape(2, 3, 3, 3)
    assert det3(A).shape == (2, 3) and inv3(A).shape == (2, 3, 3, 3)
    assert torch.allclose(det3(A), torch.linalg.det(A), rtol=1e-13)
    assert real_3x3(A) and real_3x3(A[0, 0])
    assert not real_3x3(torch.ones(4, 2, 2)) and not real_3x3(torch.ones(3, 3, dtype=torch.int64))
    assert not real_3x3(torch.ones(3, 3, dtype=torch.complex64)) and not real_3x3([[1.0]])


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_a_singular_matrix_has_zero_determinant_and_no_finite_inverse(dtype):
    A = torch.tensor([[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 1.0, 5.0]], dtype=dtype)
    assert det3(A) == 0
    assert not torch.isfinite(inv3(A)).all()
