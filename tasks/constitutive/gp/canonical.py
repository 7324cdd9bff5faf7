"""Canonical forms of genomes: one key per law form, whatever its constants or the order of its
commutative arguments, so the proposer evaluates a form once.

The key ignores parameter values (keeping their transforms, which fix a constant's sign and
range) and the terms' coefficients, sorts the terms (a sum) and the arguments of commutative
operations, writes a blend of ``a`` to ``b`` as one of ``b`` to ``a`` (its weight w becomes
1 - w, again a weight), undoes a double transpose and writes the ways of saying F as F.
"""

from __future__ import annotations

from tasks.constitutive.gp import grammar
from tasks.constitutive.gp.genome import IDENTITIES, Expr, Genome, Node, Param
from tasks.constitutive.gp.grammar import MATRIX

#: Operations whose two arguments commute, by value type (matmul does not).
COMMUTATIVE = {"add", "mul"}

Key = tuple


def form(genome: Genome) -> Key:
    """The canonical key of ``genome``'s form."""
    return (genome.kind, tuple(sorted((_key(t.expr, MATRIX) for t in genome.terms), key=repr)))


def _key(expr: Expr, value_type: str) -> Key:
    if isinstance(expr, Param):
        return ("#", expr.transform)
    if value_type == MATRIX and expr in IDENTITIES:
        return ("F",)
    if expr.op == "T" and isinstance(inner := expr.children[0], Node) and inner.op == "T":
        return _key(inner.children[0], value_type)
    args = grammar.OPS[value_type][expr.op].args
    children = [_key(child, arg) for child, arg in zip(expr.children, args, strict=True)]
    if expr.op in COMMUTATIVE or expr.op == "blend":
        children[-2:] = sorted(children[-2:], key=repr)
    return (expr.op, *children)
