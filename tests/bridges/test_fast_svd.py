"""The bridge's batched Jacobi SVD serves bridges.linalg.svd in float32 (run in a float32
subprocess), as accurate as LAPACK allows in float32 on every kind of matrix; its reverse kernel
(``svd3_backward``, float64 here) passes central differences, and where singular values coincide
it gives what ``bridges.linalg`` documents."""

import json
import subprocess
import sys

import pytest
import torch

from bridges.fast_svd import taichi_svd_backward
from bridges.linalg import svd

SCRIPT = """
import json

import torch
import taichi_mpm as tm
from bridges.fast_svd import taichi_svd
from bridges.linalg import svd, stable_linalg

before = taichi_svd(torch.eye(3).expand(4, 3, 3))  # no Taichi runtime yet: None
tm.init(precision="float32")
torch.manual_seed(0)
F = torch.eye(3) + 0.4 * torch.randn(500, 3, 3)
F[:7] = -F[:7]  # inverted
U, S, Vh = taichi_svd(F)
U2, S2, Vh2 = svd(F)
with stable_linalg():
    U3, S3, Vh3 = torch.linalg.svd(F)
reference = torch.linalg.svdvals(F.double())
print(json.dumps({
    "before": before is None,
    "float64": taichi_svd(F.double()) is None,
    "reconstruction": (U @ torch.diag_embed(S) @ Vh - F).abs().max().item(),
    "rotations": (torch.linalg.det(U) - 1).abs().max().item()
    + (torch.linalg.det(Vh) - 1).abs().max().item(),
    "values": (S.abs().double() - reference).abs().max().item(),
    "sorted": bool((S[:, :2].abs() >= S[:, 1:].abs()).all()),
    "negative_when_inverted": bool((S[:, 2] < 0).eq(torch.linalg.det(F) < 0).all()),
    "svd_uses_it": (S2 - S).abs().max().item(),
    "patched_unsigned": bool((S3 >= 0).all()),
    "patched_reconstruction": (U3 @ torch.diag_embed(S3) @ Vh3 - F).abs().max().item(),
}))
rotations = torch.linalg.qr(torch.randn(300, 3, 3)).Q
rotations = rotations * torch.linalg.det(rotations)[:, None, None]
families = {  # each scaled to unit largest singular value
    "general": torch.randn(300, 3, 3),
    "near identity": torch.eye(3) + 1e-4 * torch.randn(300, 3, 3),
    "identity": torch.eye(3).expand(8, 3, 3).contiguous(),
    "repeated": rotations @ torch.diag(torch.tensor([2.0, 1.0, 1.0])) @ rotations.mT,
    "rank two": torch.randn(300, 3, 2) @ torch.randn(300, 2, 3),
    "rank one": torch.randn(300, 3, 1) @ torch.randn(300, 1, 3),
    "zero": torch.zeros(4, 3, 3),
    "large": 1e3 * (torch.eye(3) + 0.3 * torch.randn(300, 3, 3)),
}
errors = {}
for name, A in families.items():
    U, S, Vh = taichi_svd(A)
    scale = torch.linalg.svdvals(A.double())[:, :1].clamp(min=1e-30)
    errors[name] = {
        "reconstruction": ((U @ torch.diag_embed(S) @ Vh - A).abs().amax((1, 2)) / scale[:, 0])
        .max().item(),
        "values": ((S.abs().double() - torch.linalg.svdvals(A.double())) / scale).abs().max()
        .item(),
        "orthogonal": max((M.mT @ M - torch.eye(3)).abs().max().item() for M in (U, Vh)),
        "rotations": max((torch.linalg.det(M) - 1).abs().max().item() for M in (U, Vh)),
        "sorted": bool((S[:, :2].abs() >= S[:, 1:].abs() - 1e-6 * scale).all()),
    }
print(json.dumps(errors))
"""


@pytest.fixture(scope="module")
def measured() -> list[str]:
    """The script's two JSON lines (its float32 Taichi process runs once for both tests)."""
    out = subprocess.run([sys.executable, "-c", SCRIPT], check=True, capture_output=True, text=True)
    return out.stdout.strip().splitlines()[-2:]


@pytest.mark.slow
def test_taichi_svd_in_float32(measured):
    result = json.loads(measured[0])
    assert result["before"] and result["float64"]
    assert result["reconstruction"] < 1e-5
    assert result["rotations"] < 1e-5
    assert result["values"] < 1e-5
    assert result["sorted"] and result["negative_when_inverted"]
    assert result["svd_uses_it"] == 0.0
    assert result["patched_unsigned"] and result["patched_reconstruction"] < 1e-5


@pytest.mark.slow
def test_taichi_svd_on_every_kind_of_matrix(measured):
    families = json.loads(measured[1])
    assert len(families) == 8
    for name, errors in families.items():
        assert errors["reconstruction"] < 2e-5, name  # relative to the largest singular value
        assert errors["values"] < 1e-5, name
        assert errors["orthogonal"] < 1e-5 and errors["rotations"] < 1e-5, name
        assert errors["sorted"], name


# ----------------------------------------------------------------- the reverse, directly

DTYPE = torch.float64
TOL_FACTOR = torch.finfo(DTYPE).eps ** 0.5  # the clamp of bridges.linalg: 1.5e-8 here
WEIGHTS = torch.tensor([[0.3, -1.2, 0.7], [2.0, 0.1, -0.4], [-0.9, 0.5, 1.6]], dtype=DTYPE)


def _rotation(seed: int) -> torch.Tensor:
    Q = torch.linalg.qr(torch.randn(3, 3, generator=torch.Generator().manual_seed(seed),
                                    dtype=DTYPE)).Q  # fmt: skip
    return Q * torch.linalg.det(Q)


def _matrix(values: tuple[float, float, float]) -> torch.Tensor:
    """R1 diag(values) R2 with fixed rotations R1, R2: given singular values (signed)."""
    return _rotation(1) @ torch.diag(torch.tensor(values, dtype=DTYPE)) @ _rotation(2)


#: Losses of the signed SVD that are smooth functions of F wherever it is used below: they
#: change neither when a pair (u_i, v_i) flips sign nor when equal singular values mix.
LOSSES = {
    # an odd function of the signed singular values as a matrix function: U h(S) Vh
    "stretch": lambda U, S, Vh: (WEIGHTS * ((U * (S**3 + 0.5 * S)[None, :]) @ Vh)).sum(),
    # the polar rotation
    "rotation": lambda U, S, Vh: (WEIGHTS * (U @ Vh)).sum(),
    # a symmetric function of the singular values
    "energy": lambda U, S, Vh: (torch.log(S.abs()) ** 2).sum() + S.prod(),
    # singular values one by one: smooth only where they are distinct
    "values": lambda U, S, Vh: (torch.tensor([0.3, -0.7, 1.1], dtype=DTYPE) * S).sum(),
}
ANYWHERE = ("stretch", "rotation", "energy")
MATRICES = {
    "random": torch.eye(3, dtype=DTYPE) + 0.4 * torch.randn(
        3, 3, generator=torch.Generator().manual_seed(3), dtype=DTYPE),
    "inverted": _matrix((1.4, 0.9, -0.6)),
    "gap 1e-4": _matrix((1.3, 1.0 + 1e-4, 1.0)),
    "gap 1e-6": _matrix((1.3, 1.0 + 1e-6, 1.0)),
    "gaps 1e-4 at a rotation": _matrix((1.0 + 1e-4, 1.0, 1.0 - 1e-4)),
}  # fmt: skip
CASES = [(matrix, loss) for matrix in MATRICES for loss in LOSSES
         if loss in ANYWHERE or matrix in ("random", "inverted")]  # fmt: skip


def _taichi_gradient(loss, F: torch.Tensor) -> torch.Tensor:
    """dL/dF of ``loss(svd(F))`` by the Taichi reverse kernel alone: the loss's gradients
    with respect to U, S and Vh from torch, then ``svd3_backward``."""
    U, S, Vh = (t.detach().requires_grad_(True) for t in svd(F[None]))
    grads = torch.autograd.grad(loss(U[0], S[0], Vh[0]), [U, S, Vh], allow_unused=True)
    fast = taichi_svd_backward(U.detach(), S.detach(), Vh.detach(), tuple(grads), TOL_FACTOR)
    assert fast is not None  # the tests run a float64 Taichi CPU runtime
    return fast[0]


def _central_differences(loss, F: torch.Tensor, h: float = 1e-6) -> torch.Tensor:
    grad = torch.zeros(9, dtype=DTYPE)
    for k in range(9):
        step = torch.zeros(9, dtype=DTYPE)
        step[k] = h
        plus, minus = (loss(*(t[0] for t in svd((F + sign * step.reshape(3, 3))[None])))
                       for sign in (1, -1))  # fmt: skip
        grad[k] = (plus - minus) / (2 * h)
    return grad.reshape(3, 3)


@pytest.mark.parametrize(("matrix", "loss"), CASES, ids=[f"{m}, {n}" for m, n in CASES])
def test_the_svd_reverse_kernel_passes_central_differences(matrix, loss):
    """Where singular values are distinct, down to a gap of 1e-6 (above the clamp's 1.5e-8),
    the reverse is the exact gradient."""
    F = MATRICES[matrix]
    exact = _taichi_gradient(LOSSES[loss], F)
    numeric = _central_differences(LOSSES[loss], F)
    torch.testing.assert_close(exact, numeric, rtol=0, atol=1e-7 * numeric.abs().max())


@pytest.mark.parametrize("values", [(2.0, 1.0, 1.0), (1.0, 1.0, 1.0), (1.3, 1.0 + 1e-10, 1.0)],
                         ids=["two equal", "all equal", "gap 1e-10"])  # fmt: skip
def test_the_svd_reverse_kernel_where_singular_values_coincide(values):
    """At a gap below the clamp, as bridges.linalg documents: the polar rotation's and a
    symmetric function's gradients stay exact, and a matrix function's stays finite (its
    (h_j - h_i) / (s_j - s_i) term is divided by the clamp instead)."""
    F = _matrix(values)
    for loss in ("rotation", "energy"):
        exact = _taichi_gradient(LOSSES[loss], F)
        numeric = _central_differences(LOSSES[loss], F)
        torch.testing.assert_close(exact, numeric, rtol=0, atol=1e-7 * numeric.abs().max())
    assert torch.isfinite(_taichi_gradient(LOSSES["stretch"], F)).all()
