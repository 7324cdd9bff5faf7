"""The StVK-Hencky stress in Taichi kernels equals the torch law, values and gradients.

In float64 (this session's runtime) the kernels take LAPACK's SVD and must reproduce
``bridges.laws.hencky_stress_in_torch`` and its autograd to round-off on every branch of the
law: rotations, inverted elements, singular values under the log-strain floor and under
``J_FLOOR``, and repeated singular values (the clamped SVD backward). In float32 (a subprocess)
they also take the SVD themselves, by the same Jacobi sweeps as ``bridges.fast_svd``.
"""

import json
import math
import subprocess
import sys

import pytest
import torch

from bridges.hencky import hencky_stress
from bridges.laws import StVKHencky, hencky_stress_in_torch


def _deformations(count: int, seed: int) -> torch.Tensor:
    generator = torch.Generator().manual_seed(seed)
    F = torch.eye(3, dtype=torch.float64) + 0.3 * torch.randn(
        count, 3, 3, dtype=torch.float64, generator=generator
    )
    rotations = torch.linalg.qr(torch.randn(4, 3, 3, dtype=torch.float64, generator=generator)).Q
    F[:4] = rotations * torch.linalg.det(rotations)[:, None, None]  # repeated values: all 1
    F[4] = 2.0 * torch.eye(3, dtype=torch.float64)
    F[5] = torch.diag(torch.tensor([1.2, 5e-3, 0.9], dtype=torch.float64))  # under SIGMA_FLOOR
    F[6] = torch.diag(torch.tensor([1.1, 0.8, 1e-7], dtype=torch.float64))  # under J_FLOOR
    F[7:12] = -F[7:12]  # inverted
    return F


def _lame(E, nu):
    """Shear modulus and first Lame parameter from Young's modulus and Poisson's ratio."""
    return E / (2.0 * (1.0 + nu)), E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))


def _stress_and_gradients(stress_of, F, E, nu, weights):
    F, E, nu = (t.clone().requires_grad_(True) for t in (F, E, nu))
    stress = stress_of(F, *_lame(E, nu))
    (weights * stress).sum().backward()
    return stress.detach(), F.grad, E.grad, nu.grad


def test_kernels_equal_the_torch_law_in_float64():
    F = _deformations(200, seed=0)
    E = torch.tensor(3e5, dtype=torch.float64)
    nu = torch.tensor(0.3, dtype=torch.float64)
    generator = torch.Generator().manual_seed(1)
    weights = torch.randn(200, 3, 3, dtype=torch.float64, generator=generator)
    fused = _stress_and_gradients(hencky_stress, F, E, nu, weights)
    reference = _stress_and_gradients(hencky_stress_in_torch, F, E, nu, weights)
    for name, got, expected in zip(["stress", "F", "E", "nu"], fused, reference, strict=True):
        scale = expected.abs().max()
        assert scale > 0, name
        torch.testing.assert_close(got, expected, rtol=1e-10, atol=1e-11 * scale, msg=name)


def test_kernels_match_finite_differences():
    F = _deformations(12, seed=2)[7:].clone()  # inverted and general, distinct values
    E = torch.tensor(2.0, dtype=torch.float64)
    nu = torch.tensor(0.25, dtype=torch.float64)

    def law(F, E, nu):
        return hencky_stress(F, *_lame(E, nu))

    inputs = tuple(t.requires_grad_(True) for t in (F, E, nu))
    assert torch.autograd.gradcheck(law, inputs, eps=1e-6, atol=1e-7, rtol=1e-6)


def test_the_law_module_runs_the_kernels():
    law = StVKHencky(E=3e5, nu=0.3, dtype=torch.float64)
    F = _deformations(20, seed=3).requires_grad_(True)
    stress = law(F)
    assert type(stress.grad_fn).__name__ == "_HenckyStressBackward"
    expected = hencky_stress_in_torch(F, *_lame(law.E, law.nu))
    torch.testing.assert_close(stress, expected, rtol=1e-12, atol=1e-6)


def test_no_kernels_for_another_precision():
    """The session's runtime is float64: a float32 batch stays with torch."""
    F = torch.eye(3).expand(4, 3, 3)
    assert hencky_stress(F, torch.tensor(1.0), torch.tensor(1.0)) is None


FLOAT32 = """
import json
import math
import torch
import taichi_mpm as tm
from bridges.hencky import hencky_stress
from bridges.laws import hencky_stress_in_torch

tm.init(precision="float32")
generator = torch.Generator().manual_seed(0)
F = torch.eye(3) + 0.3 * torch.randn(3000, 3, 3, generator=generator)
F[:100] = -F[:100]
weights = torch.randn(3000, 3, 3, generator=generator)
mu, lam = torch.tensor(1.2e5), torch.tensor(1.7e5)
results = []
for stress_of, dtype in ((hencky_stress, torch.float32), (hencky_stress_in_torch, torch.float32),
                         (hencky_stress_in_torch, torch.float64)):
    leaf = F.to(dtype).clone().requires_grad_(True)
    stress = stress_of(leaf, mu.to(dtype), lam.to(dtype))
    (weights.to(dtype) * stress).sum().backward()
    results.append((stress.detach().double(), leaf.grad.double()))
exact = results.pop()


def error(got, expected):
    return ((got - expected).abs().max() / expected.abs().max()).item()


print(json.dumps({
    name: [error(got[i], exact[i]) for got in results] for i, name in enumerate(["stress", "grad"])
}))
"""


@pytest.mark.slow
def test_float32_kernels_take_their_own_svd_and_are_as_accurate_as_torch():
    out = subprocess.run([sys.executable, "-c", FLOAT32], capture_output=True, text=True,
                         check=True)  # fmt: skip
    errors = json.loads(out.stdout.strip().splitlines()[-1])  # (kernels, torch) vs float64
    for name, (kernels, torch_law) in errors.items():
        assert kernels < 2.0 * torch_law + 1e-6, (name, errors)


def _about_axis(axis: int, angle: float) -> torch.Tensor:
    c, s = math.cos(angle), math.sin(angle)
    i, j = [k for k in range(3) if k != axis]
    rotation = torch.eye(3, dtype=torch.float64)
    rotation[i, i], rotation[i, j], rotation[j, i], rotation[j, j] = c, -s, s, c
    return rotation


def test_the_compact_svd_keeps_rotations_of_every_kind():
    """The reverse keeps the SVD's rotations as quaternions: rotations whose quaternion comes
    from each of Shepperd's four cases (small angles; half turns about x, y and z, where the
    trace is -1) give the torch law's stress and gradients."""
    stretch = torch.diag(torch.tensor([1.3, 0.8, 1.05], dtype=torch.float64))
    rotations = [_about_axis(0, 0.2), *(_about_axis(axis, math.pi - 1e-3) for axis in range(3)),
                 *(_about_axis(axis, math.pi) for axis in range(3))]  # fmt: skip
    F = torch.stack([r @ stretch @ _about_axis(2, 0.7).T for r in rotations]
                    + [_about_axis(1, 0.4) @ stretch @ r.T for r in rotations])  # fmt: skip
    E = torch.tensor(3e5, dtype=torch.float64)
    nu = torch.tensor(0.3, dtype=torch.float64)
    weights = torch.randn(F.shape, dtype=torch.float64, generator=torch.Generator().manual_seed(4))
    fused = _stress_and_gradients(hencky_stress, F, E, nu, weights)
    reference = _stress_and_gradients(hencky_stress_in_torch, F, E, nu, weights)
    for name, got, expected in zip(["stress", "F", "E", "nu"], fused, reference, strict=True):
        torch.testing.assert_close(got, expected, rtol=1e-10, atol=1e-11 * expected.abs().max(),
                                   msg=name)  # fmt: skip
