"""bridges.linalg: signed SVD with stable gradients, polar decomposition, torch routing."""

import pytest
import torch

from bridges.linalg import polar, stable_linalg, svd, trace

DTYPE = torch.float64
WEIGHTS = torch.arange(9, dtype=DTYPE).reshape(3, 3) - 4.0


def random_F(n: int, seed: int = 0, reflections: int = 2) -> torch.Tensor:
    """Random 3x3 matrices around the identity, the last ``reflections`` with det < 0."""
    generator = torch.Generator().manual_seed(seed)
    F = torch.eye(3, dtype=DTYPE) + 0.4 * torch.randn(n, 3, 3, generator=generator, dtype=DTYPE)
    F[n - reflections :, :, 2] *= -1.0
    return F


def rotation(seed: int) -> torch.Tensor:
    generator = torch.Generator().manual_seed(seed)
    Q, _ = torch.linalg.qr(torch.randn(3, 3, generator=generator, dtype=DTYPE))
    return Q * torch.linalg.det(Q)


def with_singular_values(values: tuple[float, float, float], seed: int = 1) -> torch.Tensor:
    return rotation(seed) @ torch.diag(torch.tensor(values, dtype=DTYPE)) @ rotation(seed + 1)


def isotropic_loss(F: torch.Tensor) -> torch.Tensor:
    """Hencky energy, a log-stretch matrix function and the polar rotation, contracted."""
    U, S, Vh = svd(F)
    log_stretch = (U * torch.log(S.abs())[..., None, :]) @ Vh
    R, _ = polar(F)
    return (torch.log(S.abs()) ** 2).sum() + (WEIGHTS * (log_stretch + R)).sum()


def central_differences(f, F: torch.Tensor, h: float = 1e-6) -> torch.Tensor:
    grad = torch.zeros_like(F)
    for index in range(9):
        step = torch.zeros(9, dtype=DTYPE)
        step[index] = h
        step = step.reshape(3, 3)
        grad.view(-1)[index] = (f(F + step) - f(F - step)) / (2 * h)
    return grad


def autograd_gradient(f, F: torch.Tensor) -> torch.Tensor:
    F = F.clone().requires_grad_(True)
    (grad,) = torch.autograd.grad(f(F), F)
    return grad


def test_gradcheck_svd_and_polar():
    F = random_F(4).requires_grad_(True)
    assert torch.autograd.gradcheck(svd, (F,))
    assert torch.autograd.gradcheck(lambda F: svd(F, signed=False), (F,))
    assert torch.autograd.gradcheck(polar, (F,))


def test_signed_decomposition():
    F = random_F(32)
    U, S, Vh = svd(F)
    torch.testing.assert_close(U @ torch.diag_embed(S) @ Vh, F, rtol=0, atol=1e-13)
    ones = torch.ones(32, dtype=DTYPE)
    torch.testing.assert_close(torch.linalg.det(U), ones)
    torch.testing.assert_close(torch.linalg.det(Vh), ones)
    torch.testing.assert_close(S.abs(), torch.linalg.svdvals(F))
    assert torch.equal(torch.sign(S[:, 2]), torch.sign(torch.linalg.det(F)))
    assert (S[:, :2] > 0).all()
    R, P = polar(F)
    torch.testing.assert_close(R @ P, F)
    torch.testing.assert_close(P, P.mT)
    torch.testing.assert_close(torch.linalg.det(R), ones)


def test_unsigned_matches_torch():
    F = random_F(8)
    U, S, Vh = svd(F, signed=False)
    reference = torch.linalg.svd(F)
    for ours, theirs in zip((U, S, Vh), reference, strict=True):
        assert torch.equal(ours, theirs)


def test_trace():
    A = random_F(4)
    torch.testing.assert_close(trace(A), torch.einsum("bii->b", A))


@pytest.mark.parametrize(
    "F",
    [
        random_F(1, seed=3, reflections=0)[0],
        with_singular_values((1.3, 1.0, 0.8)),
        with_singular_values((1.0 + 1e-4, 1.0, 1.0 - 1e-4)),
        with_singular_values((1.0 + 2e-4, 1.0 + 1e-4, 0.7)),
        with_singular_values((1.0 + 1e-6, 1.0, 0.7)),
    ],
    ids=["random", "distinct", "near rotation, gaps 1e-4", "one gap 1e-4", "one gap 1e-6"],
)
def test_isotropic_gradients_match_central_differences(F):
    exact = autograd_gradient(isotropic_loss, F)
    numeric = central_differences(isotropic_loss, F)
    torch.testing.assert_close(exact, numeric, rtol=0, atol=1e-7 * numeric.abs().max())


@pytest.mark.parametrize("scale", [1.0, 2.0])
def test_gradients_finite_and_exact_at_repeated_singular_values(scale):
    F = scale * torch.eye(3, dtype=DTYPE)

    def energy(F):
        return (torch.log(svd(F)[1].abs()) ** 2).sum()

    def rotation_part(F):
        return (WEIGHTS * polar(F)[0]).sum()

    identity = torch.eye(3, dtype=DTYPE)
    torch.testing.assert_close(
        autograd_gradient(energy, F), 2 * torch.log(torch.tensor(scale)) / scale * identity
    )
    torch.testing.assert_close(
        autograd_gradient(rotation_part, F), (WEIGHTS - WEIGHTS.mT) / (2 * scale)
    )
    assert torch.isfinite(autograd_gradient(isotropic_loss, F)).all()


# ------------------------------------------------------------------------- routing


ORIGINALS = (torch.linalg.svd, torch.svd, torch.Tensor.svd)


def current() -> tuple:
    return (torch.linalg.svd, torch.svd, torch.Tensor.svd)


def rotation_gradient(decompose) -> torch.Tensor:
    """Gradient at F = I of <W, U V^T>, with U, V^T from ``decompose``."""
    return autograd_gradient(lambda F: (WEIGHTS * decompose(F)).sum(), torch.eye(3, dtype=DTYPE))


ROUTES = {
    "torch.linalg.svd": lambda F: (lambda U, S, Vh: U @ Vh)(*torch.linalg.svd(F)),
    "torch.svd": lambda F: (lambda U, S, V: U @ V.mT)(*torch.svd(F)),
    "Tensor.svd": lambda F: (lambda U, S, V: U @ V.mT)(*F.svd()),
}


@pytest.mark.parametrize("route", ROUTES)
def test_stable_linalg_routes_3x3_svds(route):
    assert not torch.isfinite(rotation_gradient(ROUTES[route])).all()
    with stable_linalg():
        grad = rotation_gradient(ROUTES[route])
    torch.testing.assert_close(grad, (WEIGHTS - WEIGHTS.mT) / 2)
    assert current() == ORIGINALS


def test_stable_linalg_keeps_torch_values_and_falls_back():
    F = random_F(4)
    A = torch.randn(2, 4, 4, dtype=DTYPE)
    with stable_linalg():
        routed = torch.linalg.svd(F), torch.svd(F), F.svd()
        fallbacks = torch.linalg.svd(A), torch.svd(A), torch.svd(F, compute_uv=False)
    for ours, theirs in zip(routed, (torch.linalg.svd(F), torch.svd(F), F.svd()), strict=True):
        for a, b in zip(ours, theirs, strict=True):
            assert torch.equal(a, b)
    references = torch.linalg.svd(A), torch.svd(A), torch.svd(F, compute_uv=False)
    for ours, theirs in zip(fallbacks, references, strict=True):
        for a, b in zip(ours, theirs, strict=True):
            assert torch.equal(a, b)


def test_stable_linalg_is_reentrant_and_restores_after_errors():
    with stable_linalg():
        routed = current()
        assert routed != ORIGINALS
        with stable_linalg():
            assert current() == routed
        assert current() == routed
    assert current() == ORIGINALS
    assert "svd" not in torch.Tensor.__dict__
    with pytest.raises(RuntimeError, match="inside"), stable_linalg():
        raise RuntimeError("inside")
    assert current() == ORIGINALS


@pytest.mark.parametrize("missing", [None, 0, 1, 2])
def test_taichi_svd_backward_equals_the_torch_formula(missing):
    """The one-pass Taichi backward gives torch's clamped formula, repeated values included."""
    from bridges.fast_svd import taichi_svd_backward
    from bridges.linalg import svd_backward

    F = torch.cat([random_F(40, seed=5), with_singular_values((1.0, 1.0, 0.5))[None],
                   with_singular_values((2.0, 2.0 + 1e-9, 2.0))[None]])  # fmt: skip
    U, S, Vh = svd(F)
    generator = torch.Generator().manual_seed(9)
    grads = [torch.randn(t.shape, generator=generator, dtype=DTYPE) for t in (U, S, Vh)]
    if missing is not None:
        grads[missing] = None
    tol_factor = torch.finfo(DTYPE).eps ** 0.5
    fast = taichi_svd_backward(U, S, Vh, tuple(grads), tol_factor)
    assert fast is not None  # the tests run a float64 Taichi CPU runtime
    expected = svd_backward(U, S, Vh, *grads)
    torch.testing.assert_close(fast, expected, rtol=1e-9, atol=1e-9)
