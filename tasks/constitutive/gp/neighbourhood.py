"""The forms one change away from a fitted law, listed in a fixed order.

Random mutation reaches the neighbours of the form that fits best only by chance; the proposer
tries them one after another (:func:`neighbours`), each from the parent's fitted values, so a
variant of a textbook law (a sand with cohesion, a stress with another volumetric part) is
fitted systematically once its plain form leads. Every new constant starts where the variant
is the parent's own law, or close to it: the fit begins at the parent's loss and can only
improve on it.

Plastic laws, in this order:

1. **a shifted apex**: each ``cone`` made a ``shifted_cone`` whose apex sits at a volumetric
   strain a instead of 0, starting at 0 (the parent itself): the return applied about the point
   a / 3 of the hydrostatic axis, as cohesion moves a Drucker-Prager cone's apex. Two free
   shifts, into the return and back out of it, would not do: where they differ, every strain
   inside the cone drifts by the difference at every step;
2. **a threshold that grows with compression**: each return's radius or slope r written
   ``r - k min(tr x, 0)`` with k small (a pressure-dependent yield, hardening under load);
3. **a further correction** at a small weight: each small form (:func:`.enumeration.small_forms`)
   that holds a return, then the volumetric reset ``from_strain(vol(eps))`` (a fluid's);
4. **one operation swapped** for each other of its signature (add and sub, cone and
   cylinder, eps and sigma).

Elastic laws: each term replaced by each other listed admissible form at its modulus (another
volumetric or shear part), then each listed form added as a further term at a hundredth of the
largest modulus, then the swaps; every neighbour admissible (:mod:`.admissible`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterator
from dataclasses import replace

from tasks.constitutive.gp import grammar
from tasks.constitutive.gp.admissible import admissible
from tasks.constitutive.gp.canonical import form
from tasks.constitutive.gp.elastic_forms import FORMS
from tasks.constitutive.gp.enumeration import small_forms
from tasks.constitutive.gp.genome import (
    Genome,
    Node,
    Param,
    Term,
    fits,
    from_json,
    graft_term,
    sites,
    with_term,
)
from tasks.constitutive.gp.grammar import PRINCIPAL

#: A shifted apex is written ``s tanh(u)``, u starting at 0 and the scale s at e^APEX_SCALE =
#: 0.05, a volumetric strain's size: a fit's first step (L-BFGS moves its raw values by about
#: 1 in all) would move a bare constant far past every strain of the scene. (One 5-epoch fit
#: of observed-cohesive's shifted cone from the plain cone's fitted 6.6e-4 reaches 4.0e-5,
#: ``python benchmarks/apex_fit.py``; the same fit at e^-4 reached 1.1e-4; the floor is
#: 5.05e-6.)
APEX_SCALE = -3.0
#: Returns with a radius or slope (their second argument) that may grow with compression.
RETURNS = ("cone", "cylinder", "shrink")
#: Raw start of a pressure term's log-coefficient: e^-4, a slope of 0.02.
PRESSURE_START = -4.0
#: Starting weight of an added plastic correction, and the raw value of its log constants:
#: e^-3.5 = 0.03, the middle of the plastic start range (``grammar.KIND_INITIAL``).
ADDED_WEIGHT, ADDED_CONSTANT = 0.1, -3.5
#: An added elastic term's modulus as a share of the law's largest one.
ADDED_MODULUS = 0.01


def neighbours(genome: Genome) -> Iterator[tuple[Genome, str]]:
    """``genome``'s neighbours, in the module's order, with what changed in words: each form
    once, none of ``genome``'s own form, each within the limits on size
    (:func:`.genome.fits`) and, elastic, admissible."""
    listing = _elastic(genome) if genome.kind == "elastic" else _plastic(genome)
    seen = {form(genome)}
    for child, change in listing:
        key = form(child)
        if key in seen or not fits(child) or (genome.kind == "elastic" and not admissible(child)):
            continue
        seen.add(key)
        yield child, change


def _plastic(genome: Genome) -> Iterator[tuple[Genome, str]]:
    yield from _shifted_apices(genome)
    yield from _pressure_thresholds(genome)
    present = {t.expr for t in genome.terms}
    for term in added_corrections():
        if term.expr not in present:
            block = term.expr.children[0]
            assert isinstance(block, Node)
            change = f"added a small correction ({block.op} of the strain)"
            yield replace(genome, terms=(*genome.terms, term)), change
    yield from _swaps(genome)


@functools.cache
def added_corrections() -> tuple[Term, ...]:
    """The plastic terms a neighbour adds: each small form that holds a return (a cone, a
    cylinder, a radial shrink), then the volumetric reset, at weight :data:`ADDED_WEIGHT`, their
    constants at :data:`ADDED_CONSTANT`."""
    forms = small_forms("plastic")
    returns = [g for g in forms if any(_returns(g, RETURNS))]
    reset = Node("from_strain", (Node("vol", (Node("eps"),)),))
    terms = [g.terms[0] for g in returns] + [Term(Param("unit", 1.0), reset)]
    return tuple(
        Term(Param("unit", ADDED_WEIGHT), _with_constants(term.expr, ADDED_CONSTANT))
        for term in terms
    )


@functools.cache
def _listed_elastic() -> tuple[Node, ...]:
    """The expressions of the listed admissible elastic forms (:mod:`.elastic_forms`)."""
    return tuple(from_json(text).terms[0].expr for text, _, _ in FORMS)


def _elastic(genome: Genome) -> Iterator[tuple[Genome, str]]:
    listed = _listed_elastic()
    for index, term in enumerate(genome.terms):
        for expr in listed:
            if expr != term.expr:
                yield with_term(genome, index, replace(term, expr=expr)), "replaced one term"
    largest = max(term.coefficient.raw for term in genome.terms)
    modulus = Param("log", round(largest + math.log(ADDED_MODULUS), 4))
    present = {t.expr for t in genome.terms}
    for expr in listed:
        if expr not in present:
            yield replace(genome, terms=(*genome.terms, Term(modulus, expr))), "added a term"
    yield from _swaps(genome)


def _shifted_apices(genome: Genome) -> Iterator[tuple[Genome, str]]:
    for index, path, node in _returns(genome, ("cone",)):
        strain, slope = node.children
        apex = Node("scale", (Param("log", APEX_SCALE), Node("const", (Param("tanh", 0.0),))))
        shifted = Node("shifted_cone", (strain, slope, apex))
        yield graft_term(genome, index, path, shifted), "shifted the apex of its cone"


def _pressure_thresholds(genome: Genome) -> Iterator[tuple[Genome, str]]:
    for index, path, node in _returns(genome, RETURNS):
        strain, radius = node.children
        compression = Node("neg", (Node("sum", (strain,)),))
        pressure = Node("scale", (Param("log", PRESSURE_START), compression))
        grown = Node(node.op, (strain, Node("sub", (radius, pressure))))
        change = f"made the threshold of its {node.op} grow with compression"
        yield graft_term(genome, index, path, grown), change


def _returns(genome: Genome, ops: tuple[str, ...]) -> Iterator[tuple[int, tuple[int, ...], Node]]:
    """(term index, path, node) of every principal operation of ``genome`` named in ``ops``."""
    for index, term in enumerate(genome.terms):
        for site in sites(term.expr):
            node = site.expr
            if isinstance(node, Node) and site.value_type == PRINCIPAL and node.op in ops:
                yield index, site.path, node


def _swaps(genome: Genome) -> Iterator[tuple[Genome, str]]:
    for index, term in enumerate(genome.terms):
        for site in sites(term.expr):
            node = site.expr
            if not isinstance(node, Node):
                continue
            for name in grammar.alternatives(site.value_type, node.op, genome.kind):
                swapped = Node(name, node.children)
                yield graft_term(genome, index, site.path, swapped), f"swapped {node.op} for {name}"


def _with_constants(expr: Node | Param, raw: float) -> Node | Param:
    """``expr`` with every parameter leaf's raw value set to ``raw``."""
    if isinstance(expr, Param):
        return replace(expr, raw=raw)
    return Node(expr.op, tuple(_with_constants(child, raw) for child in expr.children))
