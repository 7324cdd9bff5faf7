"""Built-in constitutive laws and their differentiable scalar parameters.

A :class:`Material` pairs one elastic law (F -> Kirchhoff stress) with one plastic law
(F_trial -> corrected F). Every law is selected at run time, so changing the material
never recompiles a kernel: the kernels read the law kinds as integers and all scalar
parameters from one small array, :data:`PARAMETER_NAMES`, whose gradient the simulator
returns.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

#: Layout of the parameter array read by the kernels.
PARAMETER_NAMES: tuple[str, ...] = (
    "E",
    "nu",
    "yield_stress",
    "friction_angle",
    "cohesion",
    "weight_identity",
    "weight_von_mises",
    "weight_sand",
    "weight_fluid",
)
PARAMETER_INDEX = {name: i for i, name in enumerate(PARAMETER_NAMES)}


class MaterialError(ValueError):
    """A material parameter is out of its physical range."""


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise MaterialError(message)


# --------------------------------------------------------------------------- elastic


@dataclass(frozen=True)
class _Elastic:
    """Isotropic elastic law with Young's modulus ``E`` (Pa) and Poisson ratio ``nu``."""

    E: float
    nu: float
    kind = -1
    needs_svd = False

    def __post_init__(self) -> None:
        _require(
            math.isfinite(self.E) and self.E > 0,
            f"{type(self).__name__}: E={self.E} must be a positive finite Young's modulus",
        )
        _require(
            -1.0 < self.nu < 0.5,
            f"{type(self).__name__}: nu={self.nu} must lie in (-1, 0.5)",
        )

    @property
    def mu(self) -> float:
        """Shear modulus."""
        return self.E / (2.0 * (1.0 + self.nu))

    @property
    def lam(self) -> float:
        """First Lame parameter."""
        return self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))

    @property
    def bulk_modulus(self) -> float:
        """Bulk modulus K = lam + 2 mu / 3."""
        return self.lam + 2.0 * self.mu / 3.0

    def parameters(self) -> dict[str, float]:
        return {"E": self.E, "nu": self.nu}


@dataclass(frozen=True)
class LinearElastic(_Elastic):
    """Small-strain law: P = 2 mu eps + lam tr(eps) I with eps = (F + F^T)/2 - I; tau = P F^T."""

    kind = 0


@dataclass(frozen=True)
class FixedCorotated(_Elastic):
    """tau = 2 mu (F - R) F^T + lam (J - 1) J I, R the rotation of the polar decomposition."""

    kind = 1
    needs_svd = True


@dataclass(frozen=True)
class NeoHookean(_Elastic):
    """tau = mu (F F^T - I) + lam log(J) I."""

    kind = 2


@dataclass(frozen=True)
class StVKHencky(_Elastic):
    """St. Venant-Kirchhoff on the Hencky strain: tau = U (2 mu log S + lam tr(log S)) U^T."""

    kind = 3
    needs_svd = True


# --------------------------------------------------------------------------- plastic


@dataclass(frozen=True)
class NoPlasticity:
    """Purely elastic: F is left unchanged."""

    slot = "weight_identity"
    needs_svd = False

    def parameters(self) -> dict[str, float]:
        return {}


@dataclass(frozen=True)
class VonMises:
    """Von Mises return mapping on the Hencky strain with yield stress (Pa)."""

    yield_stress: float
    slot = "weight_von_mises"
    needs_svd = True

    def __post_init__(self) -> None:
        _require(
            math.isfinite(self.yield_stress) and self.yield_stress > 0,
            f"VonMises: yield_stress={self.yield_stress} must be positive (Pa)",
        )

    def parameters(self) -> dict[str, float]:
        return {"yield_stress": self.yield_stress}


@dataclass(frozen=True)
class DruckerPrager:
    """Drucker-Prager sand (Klar et al. 2016) on the Hencky strain.

    ``friction_angle`` is in degrees. ``cohesion`` (dimensionless, in units of volumetric
    log strain) shifts the apex of the yield cone: the material may expand by that much
    before it loses all stress; 0 is cohesionless sand.
    """

    friction_angle: float
    cohesion: float = 0.0
    slot = "weight_sand"
    needs_svd = True

    def __post_init__(self) -> None:
        _require(
            0.0 < self.friction_angle < 90.0,
            f"DruckerPrager: friction_angle={self.friction_angle} must be in (0, 90) degrees",
        )
        _require(
            math.isfinite(self.cohesion) and self.cohesion >= 0.0,
            f"DruckerPrager: cohesion={self.cohesion} must be >= 0",
        )

    def parameters(self) -> dict[str, float]:
        return {"friction_angle": self.friction_angle, "cohesion": self.cohesion}


@dataclass(frozen=True)
class WeaklyCompressibleFluid:
    """F is reset to J^(1/3) I each step: only volume change is remembered."""

    slot = "weight_fluid"
    needs_svd = False

    def parameters(self) -> dict[str, float]:
        return {}


PlasticLaw = NoPlasticity | VonMises | DruckerPrager | WeaklyCompressibleFluid


@dataclass(frozen=True)
class PlasticMixture:
    """Weighted sum of plastic laws: F = sum_k w_k P_k(F_trial).

    The paper's imaginary material is 0.5 von Mises + 0.3 sand + 0.2 fluid::

        PlasticMixture([(0.5, VonMises(...)), (0.3, DruckerPrager(...)),
                        (0.2, WeaklyCompressibleFluid())])
    """

    components: tuple[tuple[float, PlasticLaw], ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "components", tuple((float(w), law) for w, law in self.components))
        _require(len(self.components) > 0, "PlasticMixture: give at least one (weight, law) pair")
        slots = [law.slot for _, law in self.components]
        _require(
            len(set(slots)) == len(slots),
            "PlasticMixture: each plastic law may appear once; merge repeated laws",
        )
        for w, law in self.components:
            _require(
                math.isfinite(w) and w >= 0.0,
                f"PlasticMixture: weight {w} of {type(law).__name__} must be >= 0",
            )

    @property
    def needs_svd(self) -> bool:
        return any(law.needs_svd for _, law in self.components)

    def parameters(self) -> dict[str, float]:
        values: dict[str, float] = {}
        for w, law in self.components:
            values.update(law.parameters())
            values[law.slot] = w
        return values


ElasticLaw = LinearElastic | FixedCorotated | NeoHookean | StVKHencky


@dataclass(frozen=True)
class Material:
    """An elastic law plus a plastic law (default: none)."""

    elastic: ElasticLaw
    plastic: PlasticLaw | PlasticMixture = field(default_factory=NoPlasticity)

    @property
    def elastic_kind(self) -> int:
        return self.elastic.kind

    def parameters(self) -> dict[str, float]:
        """The differentiable parameters of this material, by name (see PARAMETER_NAMES)."""
        values = dict(self.elastic.parameters())
        values.update(self.plastic.parameters())
        return values

    def parameter_array(self) -> np.ndarray:
        """All kernel parameters; weights of plastic laws not in the material are zero."""
        array = np.zeros(len(PARAMETER_NAMES))
        if isinstance(self.plastic, PlasticMixture):
            mixture = self.plastic
        else:
            mixture = PlasticMixture(((1.0, self.plastic),))
        for name, value in {**self.elastic.parameters(), **mixture.parameters()}.items():
            array[PARAMETER_INDEX[name]] = value
        return array

    def replace(self, **values: float) -> Material:
        """A copy with some parameters changed: ``material.replace(E=2e5, yield_stress=1e4)``."""
        unknown = set(values) - set(self.parameters())
        if unknown:
            raise MaterialError(
                f"unknown parameter(s) {sorted(unknown)} for this material; "
                f"it has {sorted(self.parameters())}"
            )
        elastic = dataclasses.replace(
            self.elastic, **{k: v for k, v in values.items() if k in ("E", "nu")}
        )
        return Material(elastic=elastic, plastic=_replace_plastic(self.plastic, values))


def _replace_plastic(plastic, values: dict[str, float]):
    if isinstance(plastic, PlasticMixture):
        return PlasticMixture(
            tuple(
                (values.get(law.slot, w), _replace_plastic(law, values))
                for w, law in plastic.components
            )
        )
    own = {k: v for k, v in values.items() if k in plastic.parameters()}
    return dataclasses.replace(plastic, **own) if own else plastic
