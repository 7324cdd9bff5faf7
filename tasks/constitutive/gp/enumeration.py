"""Small laws in order of prior probability: what a search tries before random ones.

Plastic search tries one-term forms (:func:`small_forms`), elastic search pairs of admissible
one-term forms (:func:`elastic_pairs`).

Every one-term expression of at most :data:`MAX_SIZE` nodes is listed with its probability under
random generation's operation weights (:data:`grammar.OP_WEIGHTS`, each choice normalised among
the operations of its type); forms that are equal up to constants (:mod:`.canonical`, a
parameter's transform ignored too: a log and a linear radius are one form) are counted once, with
their probabilities summed; trivial terms are left out. The most probable come first, ties in a
fixed order, so a search that tries the next untried form of this list covers the small forms
systematically, which random generation does not (the chance of drawing one given five-node
form is about 1e-3).
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Iterator

from tasks.constitutive.gp import grammar
from tasks.constitutive.gp.canonical import Key, form
from tasks.constitutive.gp.elastic_forms import FORMS
from tasks.constitutive.gp.genome import Expr, Genome, Node, Param, Term, from_json, size, trivial
from tasks.constitutive.gp.grammar import MATRIX, PARAM_TYPES, WEIGHT

MAX_SIZE = 5  # nodes of an enumerated term, its parameter leaves included
LISTED = 40  # forms kept, the most probable first


def _compositions(total: int, parts: int) -> Iterator[tuple[int, ...]]:
    """Ways of writing ``total`` as an ordered sum of ``parts`` positive integers."""
    if parts == 1:
        if total >= 1:
            yield (total,)
        return
    for first in range(1, total - parts + 2):
        for rest in _compositions(total - first, parts - 1):
            yield (first, *rest)


@functools.cache
def expressions(kind: str, value_type: str, nodes: int) -> tuple[tuple[Expr, float], ...]:
    """Every expression of ``value_type`` with exactly ``nodes`` nodes, with its probability."""
    if value_type in PARAM_TYPES:
        if nodes != 1:
            return ()
        if value_type == WEIGHT:
            return ((Param("sigmoid", 0.0), 1.0),)
        total = sum(grammar.PARAM_TRANSFORMS.values())
        return tuple((Param(t, 0.0), w / total) for t, w in grammar.PARAM_TRANSFORMS.items())
    ops = list(grammar.OPS[value_type].values())
    total = sum(grammar.weight(kind, value_type, op.name) for op in ops)
    found: list[tuple[Expr, float]] = []
    for op in ops:
        chance = grammar.weight(kind, value_type, op.name) / total
        if chance == 0:
            continue
        if op.terminal:
            if nodes == 1:
                found.append((Node(op.name), chance))
            continue
        for sizes in _compositions(nodes - 1, len(op.args)):
            children = [expressions(kind, arg, n) for arg, n in zip(op.args, sizes, strict=True)]
            for combination in itertools.product(*children):
                probability = chance
                for _, p in combination:
                    probability *= p
                found.append((Node(op.name, tuple(c for c, _ in combination)), probability))
    return tuple(found)


def loose(key: Key) -> Key:
    """A canonical key with parameters' transforms dropped."""
    if key[:1] == ("#",):
        return ("#",)
    return tuple(loose(part) if isinstance(part, tuple) else part for part in key)


@functools.cache
def small_forms(kind: str) -> tuple[Genome, ...]:
    """The :data:`LISTED` most probable one-term forms of ``kind``, most probable first (their
    constants at 0, the term's coefficient at 1: callers draw starting values)."""
    chances: dict[Key, float] = {}
    likeliest: dict[Key, tuple[float, Genome]] = {}  # the form's shortest, likeliest writing
    for nodes in range(1, MAX_SIZE + 1):
        for expr, probability in expressions(kind, MATRIX, nodes):
            if not isinstance(expr, Node) or trivial(expr, kind):
                continue
            genome = Genome(kind, (Term(Param(grammar.TERM_TRANSFORM[kind], 1.0), expr),))
            key = loose(form(genome))
            chances[key] = chances.get(key, 0.0) + probability
            if key not in likeliest or (
                nodes == _size(likeliest[key][1]) and probability > likeliest[key][0]
            ):
                likeliest[key] = (probability, genome)
    ranked = sorted(chances, key=lambda key: (-chances[key], repr(key)))
    return tuple(likeliest[key][1] for key in ranked[:LISTED])


def _size(genome: Genome) -> int:
    return size(genome.terms[0].expr)


def loose_form(genome: Genome) -> Key:
    """The key :func:`small_forms` tells forms apart by (transforms ignored)."""
    return loose(form(genome))


@functools.cache
def elastic_pairs() -> tuple[Genome, ...]:
    """Two-term elastic laws from the listed admissible forms (:mod:`.elastic_forms`): first each
    form beside a pressure form (the split of every textbook hyperelastic law into a term that
    shears and one of the volume alone, as mu (b - I) + lam log(J) I), in the order of the
    forms' probability; then the other pairs, most probable first. Coefficients at 0: callers
    draw starting values."""
    forms = [(from_json(text).terms[0], chance, pressure) for text, chance, pressure in FORMS]
    split, other = [], []
    for (a, p, a_pressure), (b, q, b_pressure) in itertools.combinations(forms, 2):
        if a_pressure and b_pressure:
            continue  # no shear stiffness
        pair = Genome("elastic", (a, b))
        (split if a_pressure or b_pressure else other).append((-(p * q), repr(form(pair)), pair))
    return tuple(pair for _, _, pair in sorted(split) + sorted(other))
