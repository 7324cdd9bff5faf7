"""Variation operators: from one or two parent genomes to a child.

Each operator takes the random stream, the parent, a second parent (used by crossover only),
the temperature and returns the child, or None when it does not apply (no parameter to
perturb, no term to drop) or the child would break the limits of :func:`genome.fits`.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from dataclasses import replace

from tasks.constitutive.gp import grammar
from tasks.constitutive.gp.genome import (
    MAX_DEPTH,
    Genome,
    Node,
    Param,
    fits,
    graft_term,
    params,
    random_coefficient,
    random_expr,
    random_genome,
    random_term,
    sites,
    with_param,
)

Operator = Callable[[random.Random, Genome, Genome, float], Genome | None]
REPLACEMENT_DEPTH = 4  # depth budget of a subtree drawn to replace another
RESHAPE_DEPTH = 2  # depth budget of the new arguments of a reshaped operation
#: Standard deviation of a rescaling step at temperature 1, by the coefficient's transform (a
#: weight capped at 1 moves on its own scale, logs and logits on theirs).
RESCALE_SPREAD = {"log": 1.5, "sigmoid": 1.5, "unit": 0.3}
ADOPTION = 0.3  # chance that crossover adopts a whole term of the other parent


def _checked(genome: Genome) -> Genome | None:
    return genome if fits(genome) else None


def perturb(rng: random.Random, genome: Genome, other: Genome, temperature: float) -> Genome | None:
    """Move one parameter's starting value by a Gaussian step that grows with temperature."""
    found = params(genome)
    if not found:
        return None
    index, path, param = rng.choice(found)
    step = rng.gauss(0.0, grammar.TRANSFORMS[param.transform].spread * temperature)
    return with_param(genome, index, path, replace(param, raw=round(param.raw + step, 4)))


def rescale(rng: random.Random, genome: Genome, other: Genome, temperature: float) -> Genome | None:
    """Shift every term's coefficient by one Gaussian step: a stiffer or softer elastic law
    (all moduli times one factor), or stronger or weaker plastic corrections (all weights)."""
    if not genome.terms:
        return None
    step = rng.gauss(0.0, temperature)

    def shifted(coefficient: Param) -> Param:
        raw = coefficient.raw + step * RESCALE_SPREAD[coefficient.transform]
        return replace(coefficient, raw=round(raw, 4))

    terms = tuple(replace(term, coefficient=shifted(term.coefficient)) for term in genome.terms)
    return replace(genome, terms=terms)


def swap_op(rng: random.Random, genome: Genome, other: Genome, temperature: float) -> Genome | None:
    """Replace one operation by another of the same signature (add <-> sub, dev <-> vol, ...)."""
    choices = [
        (i, site, names)
        for i, term in enumerate(genome.terms)
        for site in sites(term.expr)
        if isinstance(site.expr, Node)
        and (names := grammar.alternatives(site.value_type, site.expr.op, genome.kind))
    ]
    if not choices:
        return None
    index, site, names = rng.choice(choices)
    assert isinstance(site.expr, Node)
    swapped = Node(rng.choice(names), site.expr.children)
    return _checked(graft_term(genome, index, site.path, swapped))


def reshape_op(
    rng: random.Random, genome: Genome, other: Genome, temperature: float
) -> Genome | None:
    """Replace one operation by another of its type whose first argument has the type of its
    first child, keeping that child and drawing the other arguments afresh (vol(eps) becomes
    cylinder(eps, r) or add(eps, x)): a step between forms of different arity."""
    choices = []
    for i, term in enumerate(genome.terms):
        for site in sites(term.expr):
            if not isinstance(site.expr, Node) or not site.expr.children:
                continue
            first = grammar.OPS[site.value_type][site.expr.op].args[0]
            names = [
                op.name
                for op in grammar.OPS[site.value_type].values()
                if op.args and op.args[0] == first and op.name != site.expr.op
            ]
            if names:
                choices.append((i, site, names))
    if not choices:
        return None
    index, site, names = rng.choice(choices)
    assert isinstance(site.expr, Node)
    weights = [grammar.weight(genome.kind, site.value_type, name) for name in names]
    op = grammar.OPS[site.value_type][rng.choices(names, weights)[0]]
    budget = min(RESHAPE_DEPTH, MAX_DEPTH - site.depth)
    rest = [random_expr(rng, arg, budget, genome.kind) for arg in op.args[1:]]
    reshaped = Node(op.name, (site.expr.children[0], *rest))
    return _checked(graft_term(genome, index, site.path, reshaped))


def hoist(rng: random.Random, genome: Genome, other: Genome, temperature: float) -> Genome | None:
    """Replace a subtree by one of its own proper subtrees of the same type (matmul(x, F^T)
    becomes x): a smaller form, against bloat."""
    choices = [
        (i, site, inner)
        for i, term in enumerate(genome.terms)
        for site in sites(term.expr)
        for inner in sites(site.expr, site.value_type)
        if inner.path and inner.value_type == site.value_type and isinstance(inner.expr, Node)
    ]
    if not choices:
        return None
    index, site, inner = rng.choice(choices)
    return _checked(graft_term(genome, index, site.path, inner.expr))


def add_term(
    rng: random.Random, genome: Genome, other: Genome, temperature: float
) -> Genome | None:
    """Append a random term."""
    return _checked(replace(genome, terms=(*genome.terms, random_term(rng, genome.kind))))


def drop_term(
    rng: random.Random, genome: Genome, other: Genome, temperature: float
) -> Genome | None:
    """Remove one term."""
    if not genome.terms:
        return None
    terms = list(genome.terms)
    del terms[rng.randrange(len(terms))]
    return _checked(replace(genome, terms=tuple(terms)))


def replace_subtree(
    rng: random.Random, genome: Genome, other: Genome, temperature: float
) -> Genome | None:
    """Replace a random subtree by a fresh random one of the same type."""
    if not genome.terms:
        return None
    index = rng.randrange(len(genome.terms))
    site = rng.choice(list(sites(genome.terms[index].expr)))
    budget = min(REPLACEMENT_DEPTH, MAX_DEPTH - site.depth + 1)
    new = random_expr(rng, site.value_type, budget, genome.kind)
    return _checked(graft_term(genome, index, site.path, new))


def crossover(
    rng: random.Random, genome: Genome, other: Genome, temperature: float
) -> Genome | None:
    """Graft a subtree of ``other`` onto a site of the same type, or adopt one of its terms."""
    if not other.terms:
        return None
    if not genome.terms or rng.random() < ADOPTION:
        return _checked(replace(genome, terms=(*genome.terms, rng.choice(other.terms))))
    index = rng.randrange(len(genome.terms))
    site = rng.choice([s for s in sites(genome.terms[index].expr) if isinstance(s.expr, Node)])
    donors = [
        s.expr
        for donor in other.terms
        for s in sites(donor.expr)
        if s.value_type == site.value_type
    ]
    if not donors:
        return None
    return _checked(graft_term(genome, index, site.path, rng.choice(donors)))


def restart(rng: random.Random, genome: Genome, other: Genome, temperature: float) -> Genome | None:
    """The same form from new starting values, each drawn from its start range (a fit that
    began where the loss is flat, a yield radius above every strain, say, gets another try)."""
    found = params(genome)
    if not found:
        return None
    for index, path, param in found:
        if path is None and param.transform == grammar.TERM_TRANSFORM[genome.kind]:
            new = random_coefficient(rng, genome.kind)
        else:
            raw = round(rng.uniform(*grammar.initial(param.transform, genome.kind)), 4)
            new = replace(param, raw=raw)
        genome = with_param(genome, index, path, new)
    return genome


def fresh(rng: random.Random, genome: Genome, other: Genome, temperature: float) -> Genome | None:
    """A new random genome (the parents are ignored)."""
    return random_genome(rng, genome.kind)


OPERATORS: dict[str, Operator] = {
    "perturb": perturb,
    "rescale": rescale,
    "swap_op": swap_op,
    "reshape_op": reshape_op,
    "hoist": hoist,
    "add_term": add_term,
    "drop_term": drop_term,
    "replace_subtree": replace_subtree,
    "crossover": crossover,
    "restart": restart,
    "fresh": fresh,
}
