"""The built-in constitutive laws of :mod:`taichi_mpm`, as torch modules.

Each law reproduces ``taichi_mpm.kernels.constitutive`` formula for formula, with the same
floors and clamps, on the signed SVD of :func:`bridges.linalg.svd` (the MPM convention of
``ti.svd``). Elastic modules map F (B, 3, 3) to the Kirchhoff stress tau = P F^T; plastic
modules map the trial F (B, 3, 3) to the corrected F. Their scalar ``nn.Parameter`` objects
are named as in ``taichi_mpm.materials.PARAMETER_NAMES``; a plastic law that
reads E and nu (von Mises, Drucker-Prager) holds its own copies, and
:func:`parameter_gradients` sums same-named gradients to compare with the simulator's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import nn

import taichi_mpm
from bridges.hencky import hencky_stress
from bridges.linalg import svd, trace
from taichi_mpm.kernels.constitutive import J_FLOOR, NORM_TINY, SAND_SIGMA_FLOOR, SIGMA_FLOOR

__all__ = [
    "DruckerPrager",
    "FixedCorotated",
    "LinearElastic",
    "NeoHookean",
    "NoPlasticity",
    "PlasticMixture",
    "StVKHencky",
    "VonMises",
    "WeaklyCompressibleFluid",
    "from_material",
    "parameter_gradients",
]


def _add_parameters(module: nn.Module, dtype: torch.dtype | None, values: dict) -> None:
    """Register each value as a scalar parameter (default dtype: torch's default)."""
    dtype = dtype or torch.get_default_dtype()
    for name, value in values.items():
        module.register_parameter(name, nn.Parameter(torch.tensor(float(value), dtype=dtype)))


class _Law(nn.Module):
    """A law whose keyword arguments become scalar parameters of the given dtype."""

    def __init__(self, dtype: torch.dtype | None = None, **values: float) -> None:
        super().__init__()
        _add_parameters(self, dtype, values)


def _lame(law: nn.Module) -> tuple[torch.Tensor, torch.Tensor]:
    """Shear modulus mu and first Lame parameter lam from the law's E and nu."""
    E, nu = law.E, law.nu
    return E / (2.0 * (1.0 + nu)), E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))


def _identity(F: torch.Tensor) -> torch.Tensor:
    return torch.eye(3, dtype=F.dtype, device=F.device).expand_as(F)


def _scalar_times_identity(c: torch.Tensor, F: torch.Tensor) -> torch.Tensor:
    return c[..., None, None] * _identity(F)


def _from_singular_values(U: torch.Tensor, s: torch.Tensor, Vh: torch.Tensor) -> torch.Tensor:
    return (U * s[..., None, :]) @ Vh


def _log_strain(s: torch.Tensor, floor: float) -> torch.Tensor:
    return torch.log(torch.clamp(s.abs(), min=floor))


def _deviatoric(eps: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Deviatoric part of a principal strain and its norm (kept differentiable at zero)."""
    eps_hat = eps - eps.sum(-1, keepdim=True) / 3.0
    return eps_hat, torch.sqrt((eps_hat * eps_hat).sum(-1, keepdim=True) + NORM_TINY)


# ------------------------------------------------------------------------------- elastic


class _Elastic(_Law):
    def __init__(self, E: float, nu: float, dtype: torch.dtype | None = None) -> None:
        super().__init__(dtype, E=E, nu=nu)


class LinearElastic(_Elastic):
    """Small strain: P = 2 mu eps + lam tr(eps) I with eps = sym(F) - I; tau = P F^T."""

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        mu, lam = _lame(self)
        strain = 0.5 * (F + F.mT) - _identity(F)
        piola = 2.0 * mu * strain + lam * _scalar_times_identity(trace(strain), F)
        return piola @ F.mT


class FixedCorotated(_Elastic):
    """tau = 2 mu (F - R) F^T + lam (J - 1) J I, R the rotation of the polar decomposition."""

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        mu, lam = _lame(self)
        U, _, Vh = svd(F)
        J = torch.linalg.det(F)
        return 2.0 * mu * (F - U @ Vh) @ F.mT + lam * _scalar_times_identity((J - 1.0) * J, F)


class NeoHookean(_Elastic):
    """tau = mu (F F^T - I) + lam log(J) I, J floored at J_FLOOR."""

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        mu, lam = _lame(self)
        J = torch.clamp(torch.linalg.det(F), min=J_FLOOR)
        return mu * (F @ F.mT - _identity(F)) + lam * _scalar_times_identity(torch.log(J), F)


class StVKHencky(_Elastic):
    """StVK on the Hencky strain: P = U diag(tau_i / sigma_i) V^T, tau = P F^T.

    tau_i = 2 mu eps_i + lam tr(eps), eps_i = log(max(|sigma_i|, SIGMA_FLOOR)); sigma_i is
    pushed away from zero to magnitude J_FLOOR (keeping its sign) before the division.
    """

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        mu, lam = _lame(self)
        fused = hencky_stress(F, mu, lam)  # the same formula in Taichi, where it runs
        return fused if fused is not None else hencky_stress_in_torch(F, mu, lam)


def hencky_stress_in_torch(F: torch.Tensor, mu: torch.Tensor, lam: torch.Tensor) -> torch.Tensor:
    """:class:`StVKHencky`'s stress in torch operations: its path where Taichi does not run,
    and the reference of :func:`bridges.hencky.hencky_stress`."""
    U, sigma, Vh = svd(F)
    eps = _log_strain(sigma, SIGMA_FLOOR)
    tau = 2.0 * mu * eps + lam * eps.sum(-1, keepdim=True)
    safe = torch.where(
        sigma >= 0, torch.clamp(sigma, min=J_FLOOR), torch.clamp(sigma, max=-J_FLOOR)
    )
    return _from_singular_values(U, tau / safe, Vh) @ F.mT


# ------------------------------------------------------------------------------- plastic


class NoPlasticity(_Law):
    """Purely elastic: F is returned unchanged."""

    slot = "weight_identity"

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        return F


class VonMises(_Law):
    """Von Mises return mapping on the Hencky strain (radius yield_stress / (2 mu))."""

    slot = "weight_von_mises"

    def __init__(
        self, E: float, nu: float, yield_stress: float, dtype: torch.dtype | None = None
    ) -> None:
        super().__init__(dtype, E=E, nu=nu, yield_stress=yield_stress)

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        mu, _ = _lame(self)
        U, sigma, Vh = svd(F)
        eps = _log_strain(sigma, SIGMA_FLOOR)
        eps_hat, norm = _deviatoric(eps)
        excess = torch.clamp(norm - self.yield_stress / (2.0 * mu), min=0.0)
        return _from_singular_values(U, torch.exp(eps - excess / norm * eps_hat), Vh)


class DruckerPrager(_Law):
    """Drucker-Prager sand return mapping (Klar et al. 2016) on the Hencky strain.

    ``friction_angle`` in degrees; ``cohesion`` (volumetric log strain) shifts the cone's
    apex, where every principal strain becomes cohesion / 3.
    """

    slot = "weight_sand"

    def __init__(
        self,
        E: float,
        nu: float,
        friction_angle: float,
        cohesion: float = 0.0,
        dtype: torch.dtype | None = None,
    ) -> None:
        super().__init__(dtype, E=E, nu=nu, friction_angle=friction_angle, cohesion=cohesion)

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        mu, lam = _lame(self)
        U, sigma, Vh = svd(F)
        eps = _log_strain(sigma, SAND_SIGMA_FLOOR)
        eps_hat, norm = _deviatoric(eps)
        volumetric = eps.sum(-1, keepdim=True)
        sin_phi = torch.sin(self.friction_angle * (math.pi / 180.0))
        alpha = math.sqrt(2.0 / 3.0) * 2.0 * sin_phi / (3.0 - sin_phi)
        excess = norm + (3.0 * lam + 2.0 * mu) / (2.0 * mu) * (volumetric - self.cohesion) * alpha
        sheared = eps - torch.clamp(excess, min=0.0) / norm * eps_hat
        at_apex = (volumetric >= self.cohesion).to(eps.dtype)
        log_sigma = at_apex * self.cohesion / 3.0 + (1.0 - at_apex) * sheared
        return _from_singular_values(U, torch.exp(log_sigma), Vh)


class WeaklyCompressibleFluid(_Law):
    """F reset to J^(1/3) I (J floored at J_FLOOR): only the volume change is kept."""

    slot = "weight_fluid"

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        J = torch.clamp(torch.linalg.det(F), min=J_FLOOR)
        return _scalar_times_identity(J ** (1.0 / 3.0), F)


class PlasticMixture(nn.Module):
    """Weighted sum of plastic laws, F = sum_k w_k P_k(F_trial).

    Parameters
    ----------
    components : sequence of (weight, plastic module)
        At most one module of each plastic class. Each weight becomes the parameter named by
        the module's ``slot`` (``weight_identity``, ``weight_von_mises``, ``weight_sand``,
        ``weight_fluid``); the modules are kept under that name without ``weight_``.
    dtype : torch.dtype, optional
        dtype of the weights (default: torch's default dtype).
    """

    def __init__(
        self, components: Sequence[tuple[float, nn.Module]], dtype: torch.dtype | None = None
    ) -> None:
        super().__init__()
        slots = [law.slot for _, law in components]
        if len(set(slots)) != len(slots):
            raise ValueError("PlasticMixture: each plastic law may appear once")
        _add_parameters(self, dtype, {law.slot: weight for weight, law in components})
        self.laws = nn.ModuleDict({law.slot.removeprefix("weight_"): law for _, law in components})

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        terms = [getattr(self, f"weight_{key}") * law(F) for key, law in self.laws.items()]
        return torch.stack(terms).sum(0)


# --------------------------------------------------------------------- from taichi_mpm


_ELASTIC = {
    taichi_mpm.LinearElastic: LinearElastic,
    taichi_mpm.FixedCorotated: FixedCorotated,
    taichi_mpm.NeoHookean: NeoHookean,
    taichi_mpm.StVKHencky: StVKHencky,
}


def _plastic(law, E: float, nu: float, dtype: torch.dtype | None) -> nn.Module:
    if isinstance(law, taichi_mpm.VonMises):
        return VonMises(E, nu, law.yield_stress, dtype)
    if isinstance(law, taichi_mpm.DruckerPrager):
        return DruckerPrager(E, nu, law.friction_angle, law.cohesion, dtype)
    if isinstance(law, taichi_mpm.WeaklyCompressibleFluid):
        return WeaklyCompressibleFluid(dtype)
    return NoPlasticity(dtype)


def from_material(
    material: taichi_mpm.Material, dtype: torch.dtype | None = None
) -> tuple[nn.Module, nn.Module]:
    """Torch laws equal to a taichi_mpm material.

    Returns
    -------
    plastic, elastic : nn.Module
        A single plastic law becomes its module (its weight, fixed at 1 in taichi_mpm, is no
        parameter); a ``PlasticMixture`` becomes a :class:`PlasticMixture`.
    """
    E, nu = material.elastic.E, material.elastic.nu
    elastic = _ELASTIC[type(material.elastic)](E, nu, dtype)
    plastic = material.plastic
    if isinstance(plastic, taichi_mpm.PlasticMixture):
        components = [(w, _plastic(law, E, nu, dtype)) for w, law in plastic.components]
        return PlasticMixture(components, dtype), elastic
    return _plastic(plastic, E, nu, dtype), elastic


def parameter_gradients(*modules: nn.Module) -> dict[str, float]:
    """Sum of ``.grad`` over same-named parameters of the modules (a missing grad counts 0).

    A parameter shared by several modules counts once. The names are those of
    ``PARAMETER_NAMES``, as returned by ``taichi_mpm.Simulator.backward(...).material``.
    """
    sums: dict[str, float] = {}
    seen: set[int] = set()
    for module in modules:
        for qualified, parameter in module.named_parameters():
            if id(parameter) in seen:
                continue
            seen.add(id(parameter))
            name = qualified.rsplit(".", 1)[-1]
            grad = 0.0 if parameter.grad is None else float(parameter.grad.sum())
            sums[name] = sums.get(name, 0.0) + grad
    return sums
