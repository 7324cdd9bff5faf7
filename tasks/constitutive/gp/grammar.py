"""The typed building blocks of the genetic-programming law search.

Every expression has a value type, named for its shape in the generated code:

- ``M``: a matrix per particle, (B, 3, 3): F, the identity, the rotation R of F, the left
  Cauchy-Green tensor b = F F^T (the strain of isotropic hyperelasticity), and what
  transposes, sums, products, deviatoric and volumetric parts make of them;
- ``P``: a principal vector per particle, (B, 3), along the singular directions of F: the
  singular values, the Hencky strain (their logarithms) and what is built from them;
- ``S``: a scalar per particle, (B, 1): J, log J, traces and norms of the other types.

Parameter leaves (type ``K``, or ``W`` for a weight in (0, 1)) become ``nn.Parameter``s of the
generated law. Each stores an unconstrained raw value behind a transform that keeps it of order
one for the optimizer: ``log`` (the value is exp(raw): moduli, thresholds), ``sigmoid``
(weights, ratios in (0, 1)), ``tanh`` (signed ratios in (-1, 1)) or ``linear`` (free
coefficients). A plastic term's weight is ``unit``, min(raw, 1): it reaches 1 exactly (the
correction replaces F, as every textbook return mapping does), where a sigmoid only nears it
with a vanishing gradient.

Operations lift principal vectors back to matrices in three ways, with U, Vh the singular
vectors of F: ``frame`` (U diag(p) Vh, so ``frame(sigma)`` is F), ``from_strain``
(U diag(exp(p)) Vh, so ``from_strain(eps)`` is F: the way a return mapping rebuilds the
corrected F from a principal strain) and ``spatial`` (U diag(p) U^T, symmetric: the way an
isotropic law writes a Kirchhoff stress).
Two operations are textbook return mappings of a principal strain, written once as helper
functions of the generated module: ``cylinder`` (von Mises: the deviatoric part shortened to a
radius) and ``cone`` (Drucker-Prager: a radius proportional to the compression, and no strain
left under expansion). They are blocks the search may combine, never the answer it is given:
their radius or slope is a subtree to find and fit like any other. ``shifted_cone`` is the cone
with its apex moved to a volumetric strain given by a third argument (cohesion); random
generation never draws it, the neighbourhood of a fitted cone writes it.

Templates use ``{0}``, ``{1}``, ... for the children's values; the generated code gives every
operation its own variable, so children are always atomic expressions.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

MATRIX, PRINCIPAL, SCALAR = "M", "P", "S"
PARAM, WEIGHT = "K", "W"
VALUE_TYPES = (MATRIX, PRINCIPAL, SCALAR)
PARAM_TYPES = (PARAM, WEIGHT)
SHAPES = {MATRIX: "(B, 3, 3)", PRINCIPAL: "(B, 3)", SCALAR: "(B, 1)"}
KINDS = ("elastic", "plastic")


@dataclass(frozen=True)
class Op:
    """An operation (or a terminal, without arguments) producing a value of type ``out``.

    ``needs`` names the shared quantities of :data:`PRELUDE` the template refers to.
    """

    name: str
    out: str
    args: tuple[str, ...]
    template: str
    needs: tuple[str, ...] = ()
    helpers: tuple[str, ...] = ()  # functions of :data:`HELPERS` the template calls

    @property
    def terminal(self) -> bool:
        return not self.args


#: Quantities computed once at the top of ``forward``, in this order, with what they need.
PRELUDE: dict[str, tuple[str, tuple[str, ...]]] = {
    "svd": ("U, sigma, Vh = torch.linalg.svd(F)  # (B, 3, 3), (B, 3), (B, 3, 3)", ()),
    "eps": ("eps = torch.log(sigma.abs().clamp(min=1e-2))  # Hencky strain (B, 3)", ("svd",)),
    "R": ("R = U @ Vh  # rotation of F (B, 3, 3)", ("svd",)),
    "b": ("b = F @ F.transpose(-2, -1)  # left Cauchy-Green tensor (B, 3, 3)", ()),
    "eye": ("eye = torch.eye(3, dtype=F.dtype).expand_as(F)  # (B, 3, 3)", ()),
    "J": ("J = torch.linalg.det(F).unsqueeze(-1)  # (B, 1)", ()),
    "log_J": ("log_J = torch.log(J.clamp(min=1e-6))  # (B, 1)", ("J",)),
}

#: Module-level functions of the generated code, by name, in the order they must be defined.
HELPERS: dict[str, str] = {
    "cylinder_return": '''
def cylinder_return(strain: torch.Tensor, radius: torch.Tensor) -> torch.Tensor:
    """Principal strain (B, 3) returned onto the cylinder of ``radius`` (B, 1) around the
    hydrostatic axis: its deviatoric part shortened to at most that norm (von Mises)."""
    mean = strain.mean(-1, keepdim=True)  # (B, 1)
    deviatoric = strain - mean  # (B, 3)
    norm = torch.sqrt((deviatoric**2).sum(-1, keepdim=True) + 1e-12)  # (B, 1)
    return mean + deviatoric * (radius.clamp(min=0.0) / norm).clamp(max=1.0)  # (B, 3)
''',
    "cone_return": '''
def cone_return(strain: torch.Tensor, slope: torch.Tensor) -> torch.Tensor:
    """Principal strain (B, 3) returned onto the cone whose radius is ``slope`` (B, 1) times the
    compression -tr(strain) (Drucker-Prager, no cohesion); under expansion, to the apex: 0."""
    trace = strain.sum(-1, keepdim=True)  # (B, 1)
    inside = cylinder_return(strain, -slope * trace)  # (B, 3)
    return torch.where(trace >= 0, torch.zeros_like(strain), inside)  # (B, 3)
''',
    "shifted_cone_return": '''
def shifted_cone_return(
    strain: torch.Tensor, slope: torch.Tensor, apex: torch.Tensor
) -> torch.Tensor:
    """Principal strain (B, 3) returned onto the cone of ``slope`` (B, 1) whose apex sits at
    the volumetric strain ``apex`` (B, 1) instead of 0 (Drucker-Prager with cohesion): the
    cone's return about the point apex / 3 of the hydrostatic axis."""
    shift = apex / 3  # (B, 1)
    return cone_return(strain - shift, slope) + shift  # (B, 3)
''',
}

_NORM = "torch.sqrt(({0} ** 2).sum(-1, keepdim=True) + 1e-12)"
_MEAN_DIAGONAL = "{0}.diagonal(dim1=-2, dim2=-1).mean(-1).view(-1, 1, 1)"
_FROM_STRAIN = "U @ torch.diag_embed(torch.exp({0}.clamp(min=-5.0, max=5.0))) @ Vh"
_SPATIAL = "U @ torch.diag_embed({0}) @ U.transpose(-2, -1)"
#: radial clamp: the vector scaled down to norm s where its norm exceeds s (a projection)
_SHRINK = "{0} * ({1}.clamp(min=0.0) / " + _NORM + ").clamp(max=1.0)"


def _arithmetic(t: str) -> list[Op]:
    """Sums, differences, scaling by a parameter, blends and clamps of one value type."""
    ops = [
        Op("add", t, (t, t), "{0} + {1}"),
        Op("sub", t, (t, t), "{0} - {1}"),
        Op("scale", t, (PARAM, t), "{0} * {1}"),
        Op("blend", t, (WEIGHT, t, t), "{1} + {0} * ({2} - {1})"),
    ]
    if t != MATRIX:
        ops += [
            Op("exp", t, (t,), "torch.exp({0}.clamp(max=5.0))"),
            Op("pos", t, (t,), "torch.relu({0})"),
            Op("neg", t, (t,), "{0}.clamp(max=0.0)"),
        ]
    return ops


_OPS = [
    Op("F", MATRIX, (), "F"),
    Op("I", MATRIX, (), "eye", ("eye",)),
    Op("R", MATRIX, (), "R", ("R",)),
    Op("b", MATRIX, (), "b", ("b",)),
    *_arithmetic(MATRIX),
    Op("T", MATRIX, (MATRIX,), "{0}.transpose(-2, -1)"),
    Op("matmul", MATRIX, (MATRIX, MATRIX), "{0} @ {1}"),
    Op("smul", MATRIX, (SCALAR, MATRIX), "{0}.unsqueeze(-1) * {1}"),
    Op("dev", MATRIX, (MATRIX,), "{0} - " + _MEAN_DIAGONAL + " * eye", ("eye",)),
    Op("vol", MATRIX, (MATRIX,), _MEAN_DIAGONAL + " * eye", ("eye",)),
    Op("frame", MATRIX, (PRINCIPAL,), "U @ torch.diag_embed({0}) @ Vh", ("svd",)),
    Op("from_strain", MATRIX, (PRINCIPAL,), _FROM_STRAIN, ("svd",)),
    Op("spatial", MATRIX, (PRINCIPAL,), _SPATIAL, ("svd",)),
    Op("sigma", PRINCIPAL, (), "sigma", ("svd",)),
    Op("eps", PRINCIPAL, (), "eps", ("eps",)),
    *_arithmetic(PRINCIPAL),
    Op("smul", PRINCIPAL, (SCALAR, PRINCIPAL), "{0} * {1}"),
    Op("dev", PRINCIPAL, (PRINCIPAL,), "{0} - {0}.mean(-1, keepdim=True)"),
    Op("vol", PRINCIPAL, (PRINCIPAL,), "{0}.mean(-1, keepdim=True).expand_as({0})"),
    Op("shrink", PRINCIPAL, (PRINCIPAL, SCALAR), _SHRINK),
    Op("cylinder", PRINCIPAL, (PRINCIPAL, SCALAR), "cylinder_return({0}, {1})",
       helpers=("cylinder_return",)),
    Op("cone", PRINCIPAL, (PRINCIPAL, SCALAR), "cone_return({0}, {1})",
       helpers=("cylinder_return", "cone_return")),
    Op("shifted_cone", PRINCIPAL, (PRINCIPAL, SCALAR, SCALAR),
       "shifted_cone_return({0}, {1}, {2})",
       helpers=("cylinder_return", "cone_return", "shifted_cone_return")),
    Op("J", SCALAR, (), "J", ("J",)),
    Op("log_J", SCALAR, (), "log_J", ("log_J",)),
    Op("const", SCALAR, (PARAM,), "{0}.expand(F.shape[0], 1)"),
    *_arithmetic(SCALAR),
    Op("mul", SCALAR, (SCALAR, SCALAR), "{0} * {1}"),
    Op("sum", SCALAR, (PRINCIPAL,), "{0}.sum(-1, keepdim=True)"),
    Op("norm", SCALAR, (PRINCIPAL,), _NORM),
    Op("trace", SCALAR, (MATRIX,), "{0}.diagonal(dim1=-2, dim2=-1).sum(-1, keepdim=True)"),
]

#: Operations by value type, then name.
OPS: dict[str, dict[str, Op]] = {
    t: {op.name: op for op in _OPS if op.out == t} for t in VALUE_TYPES
}

#: Operations random generation never draws: only the neighbourhood of a fitted form
#: (:mod:`.neighbourhood`) writes them, as ``shifted_cone`` moves a cone's apex along the
#: hydrostatic axis.
_NEIGHBOURHOOD_ONLY = {(PRINCIPAL, "shifted_cone"): 0.0}

#: How often random generation picks an operation (default 1), per kind of law searched:
#: stresses of b, J and principal strains for elastic laws, strain corrections rebuilt into F
#: for plastic ones.
OP_WEIGHTS: dict[str, dict[tuple[str, str], float]] = {
    "elastic": {(MATRIX, "b"): 2.0, (MATRIX, "spatial"): 2.0, (MATRIX, "frame"): 0.5,
                (MATRIX, "from_strain"): 0.3, (MATRIX, "blend"): 0.5, (PRINCIPAL, "eps"): 2.0,
                (PRINCIPAL, "exp"): 0.5, (PRINCIPAL, "shrink"): 0.5, (PRINCIPAL, "cylinder"): 0.3,
                (PRINCIPAL, "cone"): 0.3, (SCALAR, "log_J"): 1.5, **_NEIGHBOURHOOD_ONLY},
    "plastic": {(MATRIX, "from_strain"): 8.0, (MATRIX, "frame"): 0.5, (MATRIX, "spatial"): 0.5,
                (MATRIX, "matmul"): 0.5, (MATRIX, "b"): 0.3, (MATRIX, "T"): 0.3,
                (MATRIX, "dev"): 0.3, (MATRIX, "vol"): 0.3, (PRINCIPAL, "eps"): 3.0,
                (PRINCIPAL, "sigma"): 0.5, (PRINCIPAL, "shrink"): 1.5, (PRINCIPAL, "dev"): 1.5,
                (PRINCIPAL, "vol"): 1.5, (PRINCIPAL, "cylinder"): 2.0, (PRINCIPAL, "cone"): 2.0,
                (SCALAR, "const"): 3.0, **_NEIGHBOURHOOD_ONLY},
}  # fmt: skip


@dataclass(frozen=True)
class Transform:
    """How a parameter's raw value becomes its value (``template`` in the law's code, ``value``
    for a number), and where its raw value starts."""

    prefix: str
    template: str
    meaning: str
    initial: tuple[float, float]
    spread: float  # standard deviation of a perturbation at temperature 1
    value: Callable[[float], float]


TRANSFORMS = {
    "log": Transform("log_", "torch.exp(self.{})", "natural log of a positive coefficient",
                     (-5.0, 1.0), 0.6, math.exp),
    "sigmoid": Transform("logit_", "torch.sigmoid(self.{})", "logit of a ratio in (0, 1)",
                         (-2.0, 2.0), 0.6, lambda raw: 1.0 / (1.0 + math.exp(-raw))),
    "tanh": Transform("atanh_", "torch.tanh(self.{})", "inverse tanh of a ratio in (-1, 1)",
                      (-1.5, 1.5), 0.4, math.tanh),
    "linear": Transform("", "self.{}", "a free coefficient", (-2.0, 2.0), 0.4, lambda raw: raw),
    "unit": Transform("", "self.{}.clamp(max=1.0)", "a weight, at most 1", (0.4, 1.4), 0.3,
                      lambda raw: min(raw, 1.0)),
}  # fmt: skip
#: Start ranges that differ by the kind of law searched: a positive constant of a plastic law
#: is mostly a strain-sized threshold or slope, so it starts below e^-2 = 0.135; one started
#: above every strain of a scene (a yield radius no particle reaches) gets no gradient at all.
KIND_INITIAL = {("plastic", "log"): (-5.0, -2.0)}


def initial(transform: str, kind: str) -> tuple[float, float]:
    """The raw start range of a ``transform`` parameter leaf in a ``kind`` law."""
    return KIND_INITIAL.get((kind, transform), TRANSFORMS[transform].initial)


#: Transforms of a ``K`` leaf and how often each is drawn; a ``W`` leaf is always a sigmoid.
PARAM_TRANSFORMS = {"log": 0.35, "linear": 0.35, "tanh": 0.15, "sigmoid": 0.15}

#: Raw starting range of each term's coefficient: the natural log of a modulus in Pa for
#: elastic laws (soft solids, about 3e3 to 1e6 Pa), a correction's weight for plastic laws
#: (from 1.0 up, the correction replaces F).
TERM_INITIAL = {"elastic": (8.0, 14.0), "plastic": (0.4, 1.4)}
TERM_TRANSFORM = {"elastic": "log", "plastic": "unit"}
#: Transforms a term's coefficient may have when read back: the current one first, then
#: those of earlier releases (a plastic weight was a sigmoid), so older runs still resume.
TERM_TRANSFORMS = {"elastic": ("log",), "plastic": ("unit", "sigmoid")}
TERM_NAME = {"elastic": "modulus", "plastic": "weight"}


def weight(kind: str, value_type: str, name: str) -> float:
    """Weight of operation ``name`` of ``value_type`` in random generation for ``kind``."""
    return OP_WEIGHTS[kind].get((value_type, name), 1.0)


def alternatives(value_type: str, name: str, kind: str) -> list[str]:
    """Other operations of ``value_type`` with the same argument types as ``name`` that random
    generation of ``kind`` laws draws."""
    args = OPS[value_type][name].args
    return [
        op.name
        for op in OPS[value_type].values()
        if op.args == args and op.name != name and weight(kind, value_type, op.name) > 0
    ]
