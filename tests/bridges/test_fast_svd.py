"""The bridge's batched Jacobi SVD serves bridges.linalg.svd in float32 (run in a float32
subprocess), as accurate as LAPACK allows in float32 on every kind of matrix."""

import json
import subprocess
import sys

import pytest

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
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT], check=True, capture_output=True, text=True
    )
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
