"""Material families by name: the built-in laws with defaults that move visibly.

A *family* is a constitutive law with its parameters left free: ``material_family("sand",
friction_angle=35)`` is StVK-Hencky elasticity with Drucker-Prager plasticity, every
parameter not given taking its default from :data:`DEFAULTS`. The defaults are soft enough
that the thrown-cube and paper scenes deform visibly (E = 5e4 Pa, nu = 0.3, yield stress
2e3 Pa, friction angle 30 degrees; the fluid's E = 2e4 Pa).

Used by ``scripts/make_observation.py`` (synthetic observations) and ``taichi-mpm sysid``.
"""

from __future__ import annotations

import taichi_mpm as tm
from taichi_mpm.materials import MaterialError


class FamilyError(MaterialError):
    """An unknown family or parameter; the message names the valid choices."""


#: Family name -> one-line description.
FAMILIES: dict[str, str] = {
    "elastic": "neo-Hookean elastic solid (alias of neohookean)",
    "neohookean": "neo-Hookean elastic solid: E, nu",
    "corotated": "fixed-corotated elastic solid: E, nu",
    "linear": "linear (small-strain) elastic solid: E, nu",
    "stvk": "StVK-Hencky elastic solid: E, nu",
    "plasticine": "StVK-Hencky + von Mises plasticity (alias of vonmises)",
    "vonmises": "StVK-Hencky + von Mises plasticity: E, nu, yield_stress",
    "sand": "StVK-Hencky + Drucker-Prager sand: E, nu, friction_angle (deg), cohesion",
    "fluid": "StVK-Hencky + weakly compressible fluid: E, nu (only the bulk modulus acts)",
    "imaginary": "StVK-Hencky + 0.5 von Mises + 0.3 sand + 0.2 fluid (SGA paper): 8 parameters",
}

_ELASTIC = {"E": 5e4, "nu": 0.3}
_VON_MISES = {**_ELASTIC, "yield_stress": 2e3}
_SAND = {**_ELASTIC, "friction_angle": 30.0, "cohesion": 0.0}

#: Family name -> default value of every parameter of that family.
DEFAULTS: dict[str, dict[str, float]] = {
    "elastic": dict(_ELASTIC),
    "neohookean": dict(_ELASTIC),
    "corotated": dict(_ELASTIC),
    "linear": dict(_ELASTIC),
    "stvk": dict(_ELASTIC),
    "plasticine": dict(_VON_MISES),
    "vonmises": dict(_VON_MISES),
    "sand": dict(_SAND),
    "fluid": {"E": 2e4, "nu": 0.3},
    "imaginary": {
        **_ELASTIC,
        "yield_stress": 2e3,
        "friction_angle": 30.0,
        "cohesion": 0.0,
        "weight_von_mises": 0.5,
        "weight_sand": 0.3,
        "weight_fluid": 0.2,
    },
}
assert set(DEFAULTS) == set(FAMILIES)


def family_parameters(name: str) -> tuple[str, ...]:
    """The parameters of family ``name``, in the order of :data:`DEFAULTS`."""
    return tuple(DEFAULTS[_check_family(name)])


def material_family(name: str, **params: float) -> tm.Material:
    """The material of family ``name`` with ``params`` overriding its defaults.

    Raises
    ------
    FamilyError
        For an unknown family or parameter name (the message lists the valid ones).
    MaterialError
        For a value out of its physical range (for example ``nu=0.6``).
    """
    name = _check_family(name)
    unknown = sorted(set(params) - set(DEFAULTS[name]))
    if unknown:
        raise FamilyError(
            f"unknown parameter(s) {unknown} for material family {name!r}; "
            f"its parameters are {list(DEFAULTS[name])}"
        )
    p = {**DEFAULTS[name], **{key: float(value) for key, value in params.items()}}
    elastic = {"E": p["E"], "nu": p["nu"]}
    if name in ("elastic", "neohookean"):
        return tm.Material(tm.NeoHookean(**elastic))
    if name == "corotated":
        return tm.Material(tm.FixedCorotated(**elastic))
    if name == "linear":
        return tm.Material(tm.LinearElastic(**elastic))
    hencky = tm.StVKHencky(**elastic)
    if name == "stvk":
        return tm.Material(hencky)
    if name in ("plasticine", "vonmises"):
        return tm.Material(hencky, tm.VonMises(yield_stress=p["yield_stress"]))
    if name == "sand":
        return tm.Material(
            hencky, tm.DruckerPrager(friction_angle=p["friction_angle"], cohesion=p["cohesion"])
        )
    if name == "fluid":
        return tm.Material(hencky, tm.WeaklyCompressibleFluid())
    # imaginary
    mixture = (
        (p["weight_von_mises"], tm.VonMises(yield_stress=p["yield_stress"])),
        (
            p["weight_sand"],
            tm.DruckerPrager(friction_angle=p["friction_angle"], cohesion=p["cohesion"]),
        ),
        (p["weight_fluid"], tm.WeaklyCompressibleFluid()),
    )
    return tm.Material(hencky, tm.PlasticMixture(mixture))


def parse_assignment(text: str) -> tuple[str, float]:
    """``"E=5e4"`` -> ``("E", 50000.0)``; raises ValueError with the expected form."""
    name, sep, value = text.partition("=")
    name = name.strip()
    if not sep or not name:
        raise ValueError(f"{text!r} is not of the form NAME=VALUE (for example E=5e4)")
    try:
        number = float(value)
    except ValueError:
        raise ValueError(f"{text!r}: {value.strip()!r} is not a number") from None
    if number != number or number in (float("inf"), float("-inf")):
        raise ValueError(f"{text!r}: the value must be a finite number")
    return name, number


def _check_family(name: str) -> str:
    key = str(name).strip().lower()
    if key not in FAMILIES:
        raise FamilyError(f"unknown material family {name!r}; use one of {list(FAMILIES)}")
    return key
