"""The tasks' seed laws written as genomes, so the search can vary the law it starts from.

A parent without a genome comment (the task's seed, or code a model wrote) enters the
population as the genome of its task's seed law: the identity for the plastic tasks, and for
the elastic task the linear law of ``prompt_text.ELASTIC_SEED`` at its default parameters,
tau = sym((2 mu eps + lam tr(eps) I) F^T) with eps = (F + F^T) / 2 - I. The seed's code returns
the same tensor without the symmetrisation (it differs by the antisymmetric part, which is zero
for a symmetric F). A parent carries its fitted values into the genome (see the proposer).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from tasks.constitutive.gp.genome import Genome, Node, Param, Term

#: Defaults of the elastic seed law (``prompt_text.ELASTIC_SEED``).
SEED_LOG_YOUNGS_MODULUS = 10.0
SEED_POISSONS_RATIO = 0.13
#: Poisson's ratios the genome can hold: its moduli are exp(raw), so lam must be positive.
POISSONS_RATIO_RANGE = (0.01, 0.49)


def linear_elastic(log_youngs_modulus: float, poissons_ratio: float) -> Genome:
    """Small-strain linear elasticity: 2 mu eps F^T + lam tr(eps) F^T, as two terms (Poisson's
    ratio clamped to :data:`POISSONS_RATIO_RANGE`)."""
    low, high = POISSONS_RATIO_RANGE
    E, nu = math.exp(log_youngs_modulus), min(max(poissons_ratio, low), high)
    mu, lam = E / (2 * (1 + nu)), E * nu / ((1 + nu) * (1 - 2 * nu))
    F, I = Node("F"), Node("I")  # noqa: E741 (the identity)
    F_T = Node("T", (F,))
    twice_strain = Node("sub", (Node("add", (F, F_T)), Node("add", (I, I))))
    trace_strain = Node("trace", (Node("sub", (F, I)),))
    volumetric = Node("smul", (trace_strain, I))
    return Genome(
        "elastic",
        (
            Term(Param("log", math.log(mu)), Node("matmul", (twice_strain, F_T))),
            Term(Param("log", math.log(lam)), Node("matmul", (volumetric, F_T))),
        ),
    )


def seed_genome(searched: str, fitted: Mapping[str, float] | None = None) -> Genome:
    """The genome of the seed law of a task searching ``searched`` ("elastic" or "plastic"),
    at the seed's ``fitted`` parameter values where given (else its defaults)."""
    if searched == "plastic":
        return Genome("plastic")
    values = {"log_youngs_modulus": SEED_LOG_YOUNGS_MODULUS, "poissons_ratio": SEED_POISSONS_RATIO}
    for name in values:
        value = (fitted or {}).get(name)
        if value is not None and math.isfinite(value):
            values[name] = value
    return linear_elastic(values["log_youngs_modulus"], values["poissons_ratio"])
