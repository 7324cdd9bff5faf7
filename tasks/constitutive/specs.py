"""What each constitutive-law task observes and searches (plain data, imports nothing heavy).

Ground truths follow the paper's tasks; the values are chosen so that each material's motion in
the paper scene differs clearly from the seed law's (see ``scripts/make_ground_truth.py``,
which reports the seed's loss against every ground truth).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from tasks.constitutive import prompt_text


@dataclass(frozen=True)
class KnownElastic:
    """The elastic law of the plastic tasks, given to the model: StVK on the Hencky strain."""

    E: float = 1e6
    nu: float = 0.2


KNOWN_ELASTIC = KnownElastic()
#: Ground truth of the elastic task: neo-Hookean with E = e^13 Pa, nu = 0.245.
ELASTIC_TRUTH = {"E": math.exp(13.0), "nu": 0.245}
YIELD_STRESS = 3e4  # Pa, von Mises on the Hencky strain
FRICTION_ANGLE = 25.0  # degrees, Drucker-Prager sand without cohesion
MIXTURE = (("von_mises", 0.5), ("sand", 0.3), ("fluid", 0.2))
_GIVEN = f"elastic law given: StVK on the Hencky strain, E = {KNOWN_ELASTIC.E:g} Pa, " \
    f"nu = {KNOWN_ELASTIC.nu:g}"  # fmt: skip
_PLASTIC_NAMES = {
    "von_mises": f"von Mises on the Hencky strain, yield stress {YIELD_STRESS:g} Pa",
    "sand": f"Drucker-Prager sand, friction angle {FRICTION_ANGLE:g} degrees, no cohesion",
    "fluid": "weakly compressible fluid (F reset to J^(1/3) I)",
}


@dataclass(frozen=True)
class ConstitutiveSpec:
    """One task: its name, what is searched, the ground truth (by name) and inner settings."""

    name: str
    description: str
    searched: Literal["elastic", "plastic"]
    truth: Literal["neo_hookean", "von_mises", "sand", "fluid", "mixture"]
    steps: int = 1000
    reset_every: int = 100
    epochs: int = 30
    learning_rate: float = 3e-2
    optimizer: str = "adam"

    def material(self):
        """The taichi_mpm material that generates the observation."""
        import taichi_mpm as tm

        if self.truth == "neo_hookean":
            return tm.Material(tm.NeoHookean(**ELASTIC_TRUTH), tm.NoPlasticity())
        laws = {
            "von_mises": tm.VonMises(YIELD_STRESS),
            "sand": tm.DruckerPrager(FRICTION_ANGLE),
            "fluid": tm.WeaklyCompressibleFluid(),
        }
        plastic = (
            tm.PlasticMixture([(weight, laws[name]) for name, weight in MIXTURE])
            if self.truth == "mixture"
            else laws[self.truth]
        )
        return tm.Material(tm.StVKHencky(KNOWN_ELASTIC.E, KNOWN_ELASTIC.nu), plastic)

    @property
    def truth_name(self) -> str:
        """The ground truth in words, with its values."""
        if self.truth == "neo_hookean":
            return (f"neo-Hookean, E = e^{math.log(ELASTIC_TRUTH['E']):g} Pa, "
                    f"nu = {ELASTIC_TRUTH['nu']:g}")  # fmt: skip
        if self.truth == "mixture":
            parts = " + ".join(f"{weight:g} {name.replace('_', ' ')}" for name, weight in MIXTURE)
            return f"mixture {parts} ({_GIVEN})"
        return f"{_PLASTIC_NAMES[self.truth]} ({_GIVEN})"

    @property
    def seed(self) -> str:
        return prompt_text.ELASTIC_SEED if self.searched == "elastic" else prompt_text.PLASTIC_SEED


SPECS = {
    spec.name: spec
    for spec in (
        ConstitutiveSpec(
            "elastic", "(a) non-linear elastic law of a solid, from a linear elastic seed",
            "elastic", "neo_hookean",
        ),
        ConstitutiveSpec(
            "plasticine", "(b) plasticine: its plastic return mapping, the elastic law known",
            "plastic", "von_mises",
        ),
        ConstitutiveSpec(
            "granular", "(c) plastic return mapping of a granular material (sand), elastic known",
            "plastic", "sand",
        ),
        ConstitutiveSpec(
            "fluid", "(d) plastic return mapping of a weakly compressible fluid, elastic known",
            "plastic", "fluid",
        ),
        ConstitutiveSpec(
            "imaginary", "plastic return mapping of an imaginary mixed material, elastic known",
            "plastic", "mixture", optimizer="lbfgs",
        ),
    )
}  # fmt: skip
