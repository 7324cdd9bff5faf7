"""Genomes of the law search: typed expression trees, their random generation and variation.

A :class:`Genome` is a sum of terms, each a coefficient times an expression of type ``M``:

- elastic: Kirchhoff stress = sym(sum_i modulus_i * G_i), each modulus exp(raw);
- plastic: F_corrected = F + sum_i w_i * (G_i - F), each weight sigmoid(raw), so no terms is
  the identity (no plasticity), one term a blend of F with a correction and several a
  mixture of corrections.

Trees are immutable; a node's value type follows from its position (the root is ``M``, a
child's type is the matching argument type of its parent's operation), so nodes store only the
operation's name. Genomes serialise to compact JSON and back.
"""

from __future__ import annotations

import json
import random
from collections.abc import Iterator
from dataclasses import dataclass, replace

from tasks.constitutive.gp import grammar
from tasks.constitutive.gp.grammar import MATRIX, PARAM_TYPES, WEIGHT

MAX_DEPTH = 9  # of one term's expression, its leaves included
MAX_NODES = 40  # per term
MAX_TERMS = {"elastic": 4, "plastic": 3}
MIN_TERMS = {"elastic": 1, "plastic": 0}
RANDOM_DEPTH = (3, 6)  # depth budget of a freshly drawn expression
LEAF_PROBABILITY = 0.3  # chance of stopping at a terminal before the depth budget


class GenomeError(ValueError):
    """A serialised genome is malformed or breaks the grammar."""


@dataclass(frozen=True)
class Param:
    """A fitted parameter leaf: its transform (a key of ``grammar.TRANSFORMS``) and raw value."""

    transform: str
    raw: float


@dataclass(frozen=True)
class Node:
    """An operation applied to its children (none for a terminal)."""

    op: str
    children: tuple[Node | Param, ...] = ()


Expr = Node | Param


@dataclass(frozen=True)
class Term:
    """``coefficient * expr`` (elastic) or ``coefficient * (expr - F)`` (plastic)."""

    coefficient: Param
    expr: Node


@dataclass(frozen=True)
class Genome:
    """A law: its kind ("elastic" or "plastic") and its terms."""

    kind: str
    terms: tuple[Term, ...] = ()


@dataclass(frozen=True)
class Site:
    """A subtree: where it is (child indices from the term's root), its type and depth."""

    path: tuple[int, ...]
    expr: Expr
    value_type: str
    depth: int


# ----------------------------------------------------------------------------- inspection


def sites(
    expr: Expr, value_type: str = MATRIX, depth: int = 1, path: tuple[int, ...] = ()
) -> Iterator[Site]:
    """Every subtree of ``expr`` (itself first), with its type and depth."""
    yield Site(path, expr, value_type, depth)
    if isinstance(expr, Node):
        args = grammar.OPS[value_type][expr.op].args
        for i, (child, arg) in enumerate(zip(expr.children, args, strict=True)):
            yield from sites(child, arg, depth + 1, (*path, i))


def depth(expr: Expr) -> int:
    if isinstance(expr, Param):
        return 1
    return 1 + max((depth(child) for child in expr.children), default=0)


def size(expr: Expr) -> int:
    if isinstance(expr, Param):
        return 1
    return 1 + sum(size(child) for child in expr.children)


def fits(genome: Genome) -> bool:
    """Whether ``genome`` keeps the limits on terms, depth and size, without a trivial term or
    two terms of the same expression (one coefficient would do)."""
    count = len(genome.terms)
    if not MIN_TERMS[genome.kind] <= count <= MAX_TERMS[genome.kind]:
        return False
    return len({term.expr for term in genome.terms}) == count and all(
        depth(term.expr) <= MAX_DEPTH
        and size(term.expr) <= MAX_NODES
        and not trivial(term.expr, genome.kind)
        for term in genome.terms
    )


#: Ways of writing F itself: as a plastic correction, they leave F unchanged.
IDENTITIES = (Node("F"), Node("from_strain", (Node("eps"),)), Node("frame", (Node("sigma"),)))


def trivial(expr: Node, kind: str) -> bool:
    """A term that cannot matter or says it the long way: independent of F, F itself as a
    plastic correction, or holding a wasteful operation (:func:`wasteful`)."""
    leaves = [s.expr for s in sites(expr) if isinstance(s.expr, Node) and not s.expr.children]
    if all(leaf.op == "I" for leaf in leaves) or (kind == "plastic" and expr in IDENTITIES):
        return True
    return any(isinstance(s.expr, Node) and wasteful(s.expr) for s in sites(expr))


#: Operations that change nothing when applied twice (transposing twice undoes itself).
_IDEMPOTENT = ("dev", "vol", "pos", "neg", "T")


def wasteful(node: Node) -> bool:
    """``a - a``, a blend of ``a`` with itself, a product with I, or an idempotent operation
    applied twice (its argument has its own type, so the same name is the same operation)."""
    children = node.children
    if node.op in ("sub", "blend"):
        return children[-2] == children[-1]
    if node.op == "matmul":
        return Node("I") in children
    return node.op in _IDEMPOTENT and isinstance(children[0], Node) and children[0].op == node.op


def params(genome: Genome) -> list[tuple[int, tuple[int, ...] | None, Param]]:
    """``(term index, path or None for the coefficient, param)`` of every parameter."""
    found: list[tuple[int, tuple[int, ...] | None, Param]] = []
    for i, term in enumerate(genome.terms):
        found.append((i, None, term.coefficient))
        found += [(i, s.path, s.expr) for s in sites(term.expr) if isinstance(s.expr, Param)]
    return found


def graft(expr: Expr, path: tuple[int, ...], new: Expr) -> Expr:
    """``expr`` with the subtree at ``path`` replaced by ``new``."""
    if not path:
        return new
    assert isinstance(expr, Node)
    children = list(expr.children)
    children[path[0]] = graft(children[path[0]], path[1:], new)
    return Node(expr.op, tuple(children))


def with_term(genome: Genome, index: int, term: Term) -> Genome:
    """``genome`` with term ``index`` replaced by ``term``."""
    terms = list(genome.terms)
    terms[index] = term
    return replace(genome, terms=tuple(terms))


def graft_term(genome: Genome, index: int, path: tuple[int, ...], new: Expr) -> Genome:
    """``genome`` with the subtree at ``path`` of term ``index`` replaced by ``new``."""
    term = genome.terms[index]
    expr = graft(term.expr, path, new)
    assert isinstance(expr, Node), "a term's root is an operation"
    return with_term(genome, index, replace(term, expr=expr))


def with_param(genome: Genome, index: int, path: tuple[int, ...] | None, new: Param) -> Genome:
    """``genome`` with the parameter :func:`params` locates at ``(index, path)`` (a ``None``
    path: the term's coefficient) replaced by ``new``."""
    if path is None:
        return with_term(genome, index, replace(genome.terms[index], coefficient=new))
    return graft_term(genome, index, path, new)


# ------------------------------------------------------------------------- serialisation


def to_json(genome: Genome) -> str:
    """Compact one-line JSON: ``{"kind": ..., "terms": [[coefficient, expr], ...]}``."""
    terms = [[_encode(t.coefficient), _encode(t.expr)] for t in genome.terms]
    return json.dumps({"kind": genome.kind, "terms": terms}, separators=(",", ":"))


def _encode(expr: Expr) -> list:
    if isinstance(expr, Param):
        return [expr.transform, expr.raw]
    return [expr.op, *(_encode(child) for child in expr.children)]


def from_json(text: str) -> Genome:
    """Inverse of :func:`to_json`; raises :class:`GenomeError` for anything off-grammar."""
    try:
        data = json.loads(text)
        kind = data["kind"]
        if kind not in grammar.KINDS:
            raise GenomeError(f"unknown kind {kind!r}")
        terms = tuple(
            Term(_decode_param(coefficient, grammar.TERM_TRANSFORMS[kind]), _decode(expr, MATRIX))
            for coefficient, expr in data["terms"]
        )
    except (ValueError, KeyError, TypeError, IndexError, RecursionError) as error:
        raise GenomeError(f"not a genome: {error}") from None
    genome = Genome(kind, terms)
    if not fits(genome):
        raise GenomeError("the genome exceeds the limits on terms, depth or size")
    return genome


def _decode_param(data: list, allowed: tuple[str, ...] | None = None) -> Param:
    name, raw = data
    if name not in grammar.TRANSFORMS or (allowed and name not in allowed):
        raise GenomeError(f"unexpected parameter transform {name!r}")
    if not isinstance(raw, int | float) or isinstance(raw, bool):
        raise GenomeError(f"parameter value {raw!r} is not a number")
    return Param(name, float(raw))


def _decode(data: list, value_type: str) -> Expr:
    if value_type in PARAM_TYPES:
        return _decode_param(data, ("sigmoid",) if value_type == WEIGHT else None)
    op = grammar.OPS[value_type].get(data[0])
    if op is None or len(data) != 1 + len(op.args):
        raise GenomeError(f"{data[0]!r} is no operation of type {value_type} with this arity")
    return Node(op.name, tuple(_decode(d, arg) for d, arg in zip(data[1:], op.args, strict=True)))


# ----------------------------------------------------------------------- random generation


def random_param(rng: random.Random, value_type: str, kind: str) -> Param:
    """A parameter leaf for a ``K`` or ``W`` slot of a ``kind`` law, its raw value drawn from
    its start range."""
    if value_type == WEIGHT:
        transform = "sigmoid"
    else:
        names = list(grammar.PARAM_TRANSFORMS)
        transform = rng.choices(names, [grammar.PARAM_TRANSFORMS[n] for n in names])[0]
    return Param(transform, round(rng.uniform(*grammar.initial(transform, kind)), 4))


def random_expr(
    rng: random.Random, value_type: str, budget: int, kind: str, leaf: float = LEAF_PROBABILITY
) -> Expr:
    """A random expression of ``value_type`` at most ``budget`` deep (the "grow" method), which
    stops early at a terminal with probability ``leaf`` at each level."""
    if value_type in PARAM_TYPES:
        return random_param(rng, value_type, kind)
    ops = list(grammar.OPS[value_type].values())
    if budget <= 2 or rng.random() < leaf:
        # an operation needs 2 levels, unless all its arguments are parameter leaves
        ops = [op for op in ops if op.terminal or (budget >= 2 and set(op.args) <= {*PARAM_TYPES})]
    else:
        ops = [op for op in ops if not op.terminal]
    op = rng.choices(ops, [grammar.weight(kind, value_type, op.name) for op in ops])[0]
    return Node(op.name, tuple(random_expr(rng, arg, budget - 1, kind) for arg in op.args))


def random_coefficient(rng: random.Random, kind: str) -> Param:
    """A term's coefficient for a ``kind`` law, drawn from its start range."""
    raw = round(rng.uniform(*grammar.TERM_INITIAL[kind]), 4)
    return Param(grammar.TERM_TRANSFORM[kind], raw)


def random_term(rng: random.Random, kind: str) -> Term:
    coefficient = random_coefficient(rng, kind)
    while True:
        expr = random_expr(rng, MATRIX, rng.randint(*RANDOM_DEPTH), kind, leaf=0.0)
        assert isinstance(expr, Node)
        if not trivial(expr, kind) and size(expr) <= MAX_NODES:
            return Term(coefficient, expr)


def random_genome(rng: random.Random, kind: str) -> Genome:
    """One to two random terms, within the limits."""
    while True:
        genome = Genome(kind, tuple(random_term(rng, kind) for _ in range(rng.randint(1, 2))))
        if fits(genome):
            return genome
