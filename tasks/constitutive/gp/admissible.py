"""Which elastic laws are physically admissible: frame indifferent and stress-free at rest.

Two properties every textbook hyperelastic law has, found from the expression alone (nothing is
evaluated):

- **Frame indifference.** Rotating the deformed body by Q (F becomes Q F) must rotate the
  Kirchhoff stress the same way (tau becomes Q tau Q^T). A law that fails this predicts another
  stress for a body that only turned, so it cannot hold on motions it was not fitted on.
- **No stress at rest.** Each term vanishes at F = I (mu (b - I), lam log(J) I), so the body
  at rest stays at rest whatever the moduli fitted.

:func:`frame` classifies how an expression transforms under the rotation:

- ``spatial``: Q A Q^T (b, the Kirchhoff stress, ``spatial(p)``);
- ``left``: Q A (F, its rotation R, ``frame(p)``, ``from_strain(p)``);
- ``right``: A Q^T (their transposes);
- ``material``: unchanged (F^T F);
- ``isotropic``: a multiple of the identity, unchanged and spatial at once;
- ``invariant``: a scalar or principal vector that does not change (J, the singular values);
- ``None``: none of these (the trace of F, F + b): the expression is not frame indifferent.
"""

from __future__ import annotations

import math

from tasks.constitutive.gp import grammar
from tasks.constitutive.gp.genome import Expr, Genome, Node, Param
from tasks.constitutive.gp.grammar import MATRIX

SPATIAL, LEFT, RIGHT, MATERIAL, ISOTROPIC, INVARIANT = (
    "spatial", "left", "right", "material", "isotropic", "invariant"
)  # fmt: skip
Frame = str | None

_TERMINALS = {"F": LEFT, "R": LEFT, "b": SPATIAL, "I": ISOTROPIC}
_LIFTS = {"frame": LEFT, "from_strain": LEFT, "spatial": SPATIAL}
_TRANSPOSED = {SPATIAL: SPATIAL, LEFT: RIGHT, RIGHT: LEFT, MATERIAL: MATERIAL,
               ISOTROPIC: ISOTROPIC}  # fmt: skip
#: The class of a product A @ B from the classes of A and B (an isotropic factor is neutral).
_PRODUCTS = {
    (SPATIAL, SPATIAL): SPATIAL, (SPATIAL, LEFT): LEFT, (LEFT, MATERIAL): LEFT,
    (LEFT, RIGHT): SPATIAL, (RIGHT, SPATIAL): RIGHT, (RIGHT, LEFT): MATERIAL,
    (MATERIAL, MATERIAL): MATERIAL, (MATERIAL, RIGHT): RIGHT,
}  # fmt: skip
#: Classes whose trace does not change under the rotation.
_TRACE_INVARIANT = (SPATIAL, MATERIAL, ISOTROPIC)


def frame(expr: Expr, value_type: str = MATRIX) -> Frame:
    """How ``expr``, of ``value_type``, transforms when F becomes Q F (see the module)."""
    if isinstance(expr, Param):
        return INVARIANT
    op = grammar.OPS[value_type][expr.op]
    if value_type != MATRIX:
        args = [frame(c, a) for c, a in zip(expr.children, op.args, strict=True)]
        if expr.op == "trace":
            return INVARIANT if args[0] in _TRACE_INVARIANT else None
        return INVARIANT if all(a == INVARIANT for a in args) else None
    return _matrix(expr, op.args)


def _matrix(expr: Node, arg_types: tuple[str, ...]) -> Frame:
    if not expr.children:
        return _TERMINALS[expr.op]
    args = [frame(c, a) for c, a in zip(expr.children, arg_types, strict=True)]
    if expr.op in _LIFTS:
        return _LIFTS[expr.op] if args[0] == INVARIANT else None
    if expr.op == "T":
        return _TRANSPOSED.get(args[0])
    if expr.op in ("scale", "smul"):
        return args[1] if args[0] == INVARIANT else None
    if expr.op in ("add", "sub", "blend"):  # a blend's weight is a parameter: invariant
        return _common(args[-2:])
    if expr.op == "matmul":
        a, b = args
        if a == ISOTROPIC or b == ISOTROPIC:
            return b if a == ISOTROPIC else a
        return _PRODUCTS.get((a, b))
    if expr.op == "vol":  # the mean of the diagonal times I
        return ISOTROPIC if args[0] in _TRACE_INVARIANT else None
    if expr.op == "dev":
        return args[0] if args[0] in _TRACE_INVARIANT else None
    raise ValueError(f"no frame rule for the matrix operation {expr.op!r}")


def _common(args: list[Frame]) -> Frame:
    """The class of a sum: both alike, or an isotropic one beside a spatial or material one."""
    a, b = args
    if a == ISOTROPIC or b == ISOTROPIC:
        other = b if a == ISOTROPIC else a
        return other if other in (ISOTROPIC, SPATIAL, MATERIAL) else None
    return a if a == b else None


def at_rest(expr: Expr, value_type: str = MATRIX) -> float | None:
    """``expr``'s value at F = I as a multiple c of the identity (of ones for a principal
    vector, c itself for a scalar), or None where it depends on a parameter's value."""
    if isinstance(expr, Param):
        return None
    op = grammar.OPS[value_type][expr.op]
    if not expr.children:
        return _REST_TERMINALS[expr.op]
    args = [at_rest(c, a) for c, a in zip(expr.children, op.args, strict=True)]
    if expr.op in ("scale", "smul", "mul"):  # a product: zero if either factor is
        if 0.0 in args:
            return 0.0
        return None if None in args else args[0] * args[1]
    if expr.op == "shrink":  # the vector scaled down: zero stays zero
        return 0.0 if args[0] == 0.0 else None
    if expr.op == "blend":
        return args[1] if args[1] is not None and args[1] == args[2] else None
    if None in args:
        return None
    return _REST_RULES[expr.op](*args)


_REST_TERMINALS = {"F": 1.0, "R": 1.0, "b": 1.0, "I": 1.0, "sigma": 1.0, "eps": 0.0,
                   "J": 1.0, "log_J": 0.0}  # fmt: skip
#: Values at rest of the operations not special-cased in :func:`at_rest`, from their arguments'.
_REST_RULES = {
    "add": lambda a, b: a + b, "sub": lambda a, b: a - b, "T": lambda a: a,
    "matmul": lambda a, b: a * b, "dev": lambda a: 0.0, "vol": lambda a: a,
    "frame": lambda p: p, "spatial": lambda p: p,
    "from_strain": lambda p: math.exp(min(max(p, -5.0), 5.0)),
    "exp": lambda a: math.exp(min(a, 5.0)), "pos": lambda a: max(a, 0.0),
    "neg": lambda a: min(a, 0.0), "cylinder": lambda p, s: p,
    "cone": lambda p, s: 0.0 if p >= 0 else p,
    "shifted_cone": lambda p, s, a: a / 3 if 3 * p >= a else p, "sum": lambda p: 3 * p,
    "norm": lambda p: math.sqrt(3 * p * p + 1e-12), "trace": lambda a: 3 * a,
}  # fmt: skip
REST_TOLERANCE = 1e-5  # |c| below this is no stress (a norm's epsilon gives 1e-6)


def admissible_term(expr: Node) -> bool:
    """Whether an elastic term's expression is frame indifferent (spatial, or a multiple of the
    identity) and vanishes at rest whatever its constants."""
    rest = at_rest(expr)
    return (
        frame(expr) in (SPATIAL, ISOTROPIC) and rest is not None and abs(rest) <= REST_TOLERANCE
    )


def admissible(genome: Genome) -> bool:
    """Whether every term of an elastic law is admissible (:func:`admissible_term`)."""
    return all(admissible_term(term.expr) for term in genome.terms)
