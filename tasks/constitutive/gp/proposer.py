"""The LLM-free proposer of the constitutive-law tasks: genetic programming over law code.

Stateless: a parent's genome is read back from the comment its code carries, and the run's
earlier answers come with each request (``tried``), so a resumed run proposes exactly what the
original would have. A parent without one (the task's seed law, code
written by a model) stands in as the genome of the task's seed law (:mod:`.seeds`: the identity
for plastic search, the linear law for elastic search), keeping its loss. Children start from
their parents' fitted parameter values (``Parent.parameters``), not from the values the parents
started with: the fit accumulates over generations, as in a Lamarckian (memetic) algorithm;
a plastic correction new to its parents starts from a fresh weight.

The first child of a batch at the exploit temperature (0.5 and below) continues the best
parent's fit where it had not settled: the same law from its fitted values (a fit of a few
epochs from a poor start stops short; fitted again, it goes on). Temperature sets the mix of
operators: at the exploit temperature mostly small
steps (perturbed starting values, a swapped operation, one term added or dropped) from parents
chosen by large tournaments; at the explore temperature (1.0 and above) mostly subtree
replacement, crossover and fresh random laws from parents chosen by pairs. In between, the
weights are interpolated. Perturbations grow with temperature too. A child made by changing
structure must have a form (:mod:`.canonical`) new to the run (its parents, its batch and the
earlier answers); in plastic search few children only move constants (some restart a form's
fit from new starting values), none when exploring, and most explore children first try the
most probable small forms not yet tried (:mod:`.enumeration`). Outside the opening, the first
explore child of a batch combines the terms of two or three of the best distinct parents (a
weighted mixture of plastic returns, a sum of elastic terms), the first combination not yet
tried, each term from its fitted value at its share of the whole. After the continuation, the
next exploit child is the first neighbour not yet tried of the best distinct parents
(:mod:`.neighbourhood`: a shifted apex, a threshold that grows with compression, a swapped
operation, an added term), from the parent's fitted values.

In elastic search, new structure must be physically admissible (:mod:`.admissible`: frame
indifferent, no stress at rest), and most explore children first try the next untried pair of
admissible forms (:func:`.enumeration.elastic_pairs`). A pair's moduli start where its
small-strain shear and volume response equal the best admissible parent's (every law reduces
to linear elasticity at small strain, and the fit has measured that much already); where there
is no such parent, or the pair cannot match it with positive moduli, both start at the best
parent's largest fitted modulus. A law started far from the body's stiffness may not reach it
in one fit, or blow up the simulation when too stiff.
"""

from __future__ import annotations

import itertools
import math
import random
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

from sga_agent.task import Parent
from tasks.constitutive.gp import grammar
from tasks.constitutive.gp.admissible import admissible
from tasks.constitutive.gp.canonical import Key, form
from tasks.constitutive.gp.codegen import genome_from_code, law_code, with_values
from tasks.constitutive.gp.elastic_forms import RESPONSES
from tasks.constitutive.gp.enumeration import elastic_pairs, loose_form, small_forms
from tasks.constitutive.gp.genome import (
    Genome,
    Node,
    Param,
    Term,
    fits,
    params,
    random_coefficient,
    random_genome,
    to_json,
    with_param,
)
from tasks.constitutive.gp.neighbourhood import neighbours
from tasks.constitutive.gp.seeds import seed_genome
from tasks.constitutive.gp.variation import OPERATORS, restart

LOW, HIGH = 0.5, 1.0  # temperatures of pure exploitation and pure exploration
#: Operator weights at the exploit (low) and explore (high) temperature.
EXPLOIT = {"perturb": 4.0, "rescale": 2.0, "restart": 0.0, "swap_op": 2.0, "reshape_op": 1.5,
           "hoist": 1.0, "add_term": 1.0, "drop_term": 1.0, "replace_subtree": 1.0,
           "crossover": 0.5, "fresh": 0.0}  # fmt: skip
EXPLORE = {"perturb": 1.0, "rescale": 1.0, "restart": 0.0, "swap_op": 1.0, "reshape_op": 1.5,
           "hoist": 1.0, "add_term": 1.0, "drop_term": 0.5, "replace_subtree": 3.0,
           "crossover": 3.0, "fresh": 1.5}  # fmt: skip
#: In plastic search, moves of constants alone are few (none when exploring): the fit moves
#: them anyway, and at 40 evaluations new forms paid more; of those few, some restart a form's
#: fit from new starting values (``benchmarks/gp_search.py``).
PLASTIC_CONSTANT_MOVES = {LOW: {"perturb": 1.0, "rescale": 0.5, "restart": 1.0},
                          HIGH: {"perturb": 0.0, "rescale": 0.0}}  # fmt: skip
#: Share of explore children that try the next untried small form (plastic search) or pair of
#: forms (elastic search) while there is one (:mod:`.enumeration`).
ENUMERATION_SHARE = {"plastic": 0.75, "elastic": 0.75}
#: Forms of at most this many terms count as enumerated when tried: one-term plastic forms,
#: the pairs of elastic search.
ENUMERATED_TERMS = {"plastic": 1, "elastic": 2}
PAIR_SPREAD = 0.1  # standard deviation of a pair's log-moduli around their matched values
TOURNAMENT = {LOW: 4, HIGH: 2}  # tournament sizes at either end
MIN_STEP_TEMPERATURE = 0.1  # perturbations never vanish, even at temperature 0
ATTEMPTS = 30  # tries for a child new to the parents and the batch
#: Several-term laws: the first explore child of a batch (outside the opening) combines the
#: terms of two, then three, of the best :data:`COMBINED_FROM` distinct parents, the first such
#: combination not yet tried, each term started at its fitted value times its share (1/k of k:
#: a weighted mixture of plastic returns, the average of elastic stresses).
COMBINED_FROM, COMBINED_SIZES = 4, (2, 3)
#: A fit that moved a constant (its raw value: a log, a logit) this much had not settled: the
#: first exploit child fits that law again from where it stopped (:func:`_continuation`).
MOVED = 0.01
#: The log-range an opening's plastic form is started from a second time. The start range of
#: plastic constants (``grammar.KIND_INITIAL``, e^-5 to e^-2) suits a yield strain (a yield
#: stress of a few hundredths of the stiffness); a dimensionless slope, a cone's, is of order
#: 0.1 to 1, where a fit of a few epochs from e^-4 stops short.
HIGHER_START = (-2.0, 0.0)
DESCRIPTIONS = {
    "perturb": "moved one starting value of",
    "rescale": "scaled every term's coefficient of",
    "restart": "drew new starting values for",
    "swap_op": "swapped one operation of",
    "reshape_op": "changed one operation's arity in",
    "hoist": "replaced a subtree by one of its own subtrees in",
    "add_term": "added a random term to",
    "drop_term": "dropped a term of",
    "replace_subtree": "replaced a subtree of",
    "crossover": "crossed over",
    "fresh": "drew a new random law instead of varying",
}
#: Operators that move constants only; the others must give a form new to the parents and batch.
CONSTANT_MOVES = ("perturb", "rescale", "restart")


@dataclass(frozen=True)
class _Member:
    genome: Genome
    loss: float


def exploration(temperature: float) -> float:
    """0 at or below the exploit temperature, 1 at or above the explore one, linear between."""
    return min(max((temperature - LOW) / (HIGH - LOW), 0.0), 1.0)


def operator_weights(temperature: float, searched: str) -> dict[str, float]:
    """Operator weights at ``temperature`` in a search of ``searched`` laws."""
    low, high = dict(EXPLOIT), dict(EXPLORE)
    if searched == "plastic":
        low.update(PLASTIC_CONSTANT_MOVES[LOW])
        high.update(PLASTIC_CONSTANT_MOVES[HIGH])
    x = exploration(temperature)
    return {name: (1 - x) * low[name] + x * high[name] for name in low}


class GeneticProgrammingProposer:
    """Writes new laws by mutating and crossing the genomes of the best parents.

    Parameters
    ----------
    searched : {"elastic", "plastic"}
        What the task's law maps: F to the Kirchhoff stress, or F to the corrected F.
    """

    name = "builtin:gp"

    def __init__(self, searched: str) -> None:
        if searched not in grammar.KINDS:
            raise ValueError(f"searched must be 'elastic' or 'plastic', got {searched!r}")
        self.searched = searched

    def propose_from(
        self,
        parents: Sequence[Parent],
        temperature: float,
        n: int,
        seed: int,
        tried: Sequence[str] = (),
        opening: bool = False,
    ) -> list[str]:
        """``n`` answers, each one generated law in a python block; same inputs, same answers.

        ``tried`` holds the run's earlier answers: their forms count as known, so structural
        children and the enumeration of small forms skip them. In the search's ``opening``
        every child is the next untried small form (pair of forms) while one is left; a
        plastic form with a positive constant is tried twice, the second time from higher
        constants (:data:`HIGHER_START`)."""
        rng = random.Random(seed)
        pool = [_Member(self._genome(p), _loss(p.loss)) for p in parents]
        if not pool:
            pool = [_Member(seed_genome(self.searched), math.inf)]
        earlier = [g for text in tried if (g := genome_from_code(text, self.searched))]
        known = [member.genome for member in pool] + earlier
        seen = {to_json(genome) for genome in known}
        forms = {form(genome) for genome in known}
        enumerated = ENUMERATED_TERMS[self.searched]
        listed = {loose_form(genome) for genome in known if len(genome.terms) <= enumerated}
        reference = _reference(pool) if self.searched == "elastic" else (None, math.nan)
        answers = []
        x = exploration(temperature)
        firsts: list[Callable[[], tuple[Genome, str] | None]] = []
        if x == 0:  # the best fit continued, then the best forms' next neighbour
            answered = {to_json(g) for g in earlier}
            firsts = [lambda: _continuation(parents, self.searched, answered),
                      lambda: _neighbour(pool, forms)]  # fmt: skip
        elif x == 1 and not opening:
            firsts = [lambda: _combination(pool, self.searched, forms)]
        for first in firsts:
            if len(answers) < n and (found := first()) is not None:
                child, note = found
                seen.add(to_json(child))
                forms.add(form(child))
                answers.append(_answer(law_code(child), note))
        second: list[tuple[Genome, str]] = []  # an opening form's start from higher constants
        for _ in range(n - len(answers)):
            if second:
                child, note = second.pop()
            else:
                child, note = self._next_small_form(
                    rng, temperature, listed, reference, opening
                ) or self._child(rng, pool, temperature, seen, forms)
                plastic = opening and self.searched == "plastic"
                if plastic and loose_form(child) not in listed and (
                    higher := _higher_start(rng, child)
                ) is not None:
                    second.append((higher, f"{note}, from higher constants"))
            seen.add(to_json(child))
            forms.add(form(child))
            if len(child.terms) <= enumerated:
                listed.add(loose_form(child))
            answers.append(_answer(law_code(child), note))
        return answers

    def _next_small_form(
        self,
        rng: random.Random,
        temperature: float,
        listed: set[Key],
        reference: tuple[tuple[float, float] | None, float],
        opening: bool = False,
    ) -> tuple[Genome, str] | None:
        """With a chance that grows with temperature (always in the ``opening``), the most
        probable small form (plastic) or pair of forms (elastic) not yet tried, from new
        starting values (an elastic pair's log-moduli matched to ``reference``, see
        :func:`_reference`; in the opening a plastic correction's weight at 1); None
        otherwise or when all are tried."""
        share = 1.0 if opening else exploration(temperature) * ENUMERATION_SHARE[self.searched]
        if share <= 0 or rng.random() >= share:
            return None
        elastic = self.searched == "elastic"
        listing = elastic_pairs() if elastic else small_forms(self.searched)
        for rank, genome in enumerate(listing, start=1):
            if loose_form(genome) in listed:
                continue
            if elastic:
                child = _with_moduli(rng, genome, _pair_moduli(genome, *reference))
                return child, f"tried pair of forms {rank} in order of prior probability, untried"
            child = restart(rng, genome, genome, temperature)
            assert child is not None
            if opening:
                child = _replacing(child)
            return child, f"tried small form {rank} in order of prior probability, untried"
        return None

    def _genome(self, parent: Parent) -> Genome:
        genome = genome_from_code(parent.code, self.searched)
        if genome is None:
            return seed_genome(self.searched, parent.parameters)
        return with_values(genome, parent.parameters)

    def _child(
        self,
        rng: random.Random,
        pool: list[_Member],
        temperature: float,
        seen: set[str],
        forms: set[Key],
    ) -> tuple[Genome, str]:
        """A child new to ``seen`` (genomes); unless it only moves constants, of a form new to
        ``forms`` too (a form's constants are fitted anyway)."""
        weights = operator_weights(temperature, self.searched)
        x = exploration(temperature)
        size = round((1 - x) * TOURNAMENT[LOW] + x * TOURNAMENT[HIGH])
        step = max(temperature, MIN_STEP_TEMPERATURE)
        for _ in range(ATTEMPTS):
            name = rng.choices(list(weights), list(weights.values()))[0]
            first, second = _tournament(rng, pool, size), _tournament(rng, pool, size)
            child = OPERATORS[name](rng, first.genome, second.genome, step)
            if child is not None and self.searched == "plastic":
                child = _fresh_weights(rng, child, (first.genome, second.genome))
            if child is None or to_json(child) in seen:
                continue
            if self.searched == "elastic" and name not in CONSTANT_MOVES and not admissible(child):
                continue
            if name in CONSTANT_MOVES or form(child) not in forms:
                losses = [first] if name != "crossover" else [first, second]
                note = f"{DESCRIPTIONS[name]} the parent{'s' if len(losses) > 1 else ''} "
                note += " and ".join(f"of loss {m.loss:.4g}" for m in losses)
                return child, note
        return self._random_law(rng), "drew a new random law"

    def _random_law(self, rng: random.Random) -> Genome:
        """A random law; in elastic search an admissible one."""
        while True:
            genome = random_genome(rng, self.searched)
            if self.searched != "elastic" or admissible(genome):
                return genome


def _continuation(
    parents: Sequence[Parent], searched: str, answered: set[str]
) -> tuple[Genome, str] | None:
    """The best parent written with its fitted values, to be fitted again from where its fit
    stopped, when that fit moved a constant by at least :data:`MOVED` (it had not settled)
    and no earlier answer of the run (``answered``, genomes as JSON) is that law; None
    otherwise."""
    ranked = sorted(parents, key=lambda parent: _loss(parent.loss))
    if not ranked or not math.isfinite(_loss(ranked[0].loss)):
        return None
    best = ranked[0]
    started = genome_from_code(best.code, searched)
    if started is None:
        return None
    fitted = with_values(started, best.parameters)
    moved = max(
        (
            abs(a.raw - b.raw)
            for (_, _, a), (_, _, b) in zip(params(started), params(fitted), strict=True)
        ),
        default=0.0,
    )
    if moved < MOVED or to_json(fitted) in answered:
        return None
    note = f"continued the fit of the best parent (loss {best.loss:.4g}), which moved its constants"
    return fitted, note


def _neighbour(pool: list[_Member], forms: set[Key]) -> tuple[Genome, str] | None:
    """The first neighbour (:func:`.neighbourhood.neighbours`) of the best distinct parents,
    the best first (at most :data:`COMBINED_FROM`), whose form is not in ``forms``; None when
    every one is tried."""
    for member in _best_distinct(pool)[:COMBINED_FROM]:
        for rank, (child, change) in enumerate(neighbours(member.genome), start=1):
            if form(child) not in forms:
                note = f"tried neighbour {rank} of the form of loss {member.loss:.4g}: {change}"
                return child, note
    return None


def _best_distinct(pool: list[_Member]) -> list[_Member]:
    """The parents of finite loss with terms, the best first, one per form."""
    best: list[_Member] = []
    known: set[Key] = set()
    for member in sorted(pool, key=lambda member: member.loss):
        key = form(member.genome)
        if math.isfinite(member.loss) and member.genome.terms and key not in known:
            best.append(member)
            known.add(key)
    return best


def _combination(pool: list[_Member], searched: str, forms: set[Key]) -> tuple[Genome, str] | None:
    """The first combination (:data:`COMBINED_SIZES` parents at a time, the best first) of the
    best :data:`COMBINED_FROM` distinct parents' terms whose form is not in ``forms`` and that
    keeps the limits (and, elastic, is admissible); None when every one is tried."""
    best = _best_distinct(pool)[:COMBINED_FROM]
    for size in COMBINED_SIZES:
        for chosen in itertools.combinations(best, size):
            terms = [_shared(term, size) for member in chosen for term in member.genome.terms]
            child = Genome(searched, _merged(terms))
            if not fits(child) or form(child) in forms:
                continue
            if searched == "elastic" and not admissible(child):
                continue
            losses = ", ".join(f"{member.loss:.4g}" for member in chosen)
            return child, f"combined the terms of the best forms of losses {losses}"
    return None


def _merged(terms: list[Term]) -> tuple[Term, ...]:
    """``terms`` with those of one expression as one, its coefficient the sum of theirs (of
    the moduli, or of the weights)."""
    merged: dict[Node, Term] = {}
    for term in terms:
        same = merged.get(term.expr)
        if same is None:
            merged[term.expr] = term
            continue
        a, b = same.coefficient, term.coefficient
        if a.transform == "unit":
            raw = a.raw + b.raw
        else:
            raw = max(a.raw, b.raw) + math.log1p(math.exp(-abs(a.raw - b.raw)))
        merged[term.expr] = replace(same, coefficient=replace(a, raw=round(raw, 4)))
    return tuple(merged.values())


def _shared(term: Term, parts: int) -> Term:
    """``term`` at its share of a combination of ``parts`` laws: its weight over ``parts`` (a
    plastic correction), its modulus over ``parts`` (an elastic term: its log, as an older
    run's logit of a weight, shifted by log(parts))."""
    coefficient = term.coefficient
    if coefficient.transform == "unit":
        raw = min(coefficient.raw, 1.0) / parts
    else:
        raw = coefficient.raw - math.log(parts)
    return replace(term, coefficient=replace(coefficient, raw=round(raw, 4)))


def _reference(pool: list[_Member]) -> tuple[tuple[float, float] | None, float]:
    """What the search knows of the body's stiffness, from the parents at their fitted values:
    the small-strain response (shear, volume) of the best admissible one whose terms are all
    listed forms (:data:`RESPONSES`), or None; and the best one's largest log-modulus. The
    linear seed is no reference: it does not turn with the body, and its fit can trade the
    volume response for the shear one (a Poisson's ratio of -0.2)."""
    ranked = sorted(pool, key=lambda member: member.loss)
    stiffness = max(term.coefficient.raw for term in ranked[0].genome.terms)
    for member in ranked:
        genome = member.genome
        keys = [_term_key(term) for term in genome.terms]
        if admissible(genome) and all(key in RESPONSES for key in keys):
            moduli = [math.exp(term.coefficient.raw) for term in genome.terms]
            shear, volume = (
                sum(m * RESPONSES[k][i] for m, k in zip(moduli, keys, strict=True)) for i in (0, 1)
            )
            return (shear, volume), stiffness
    return None, stiffness


def _term_key(term: Term) -> str:
    return to_json(Genome("elastic", (replace(term, coefficient=Param("log", 0.0)),)))


def _pair_moduli(
    pair: Genome, reference: tuple[float, float] | None, stiffness: float
) -> tuple[float, float]:
    """Log-moduli of ``pair`` whose small-strain response is ``reference``; both at
    ``stiffness`` where there is no reference or no positive solution."""
    if reference is not None:
        (g1, v1), (g2, v2) = (RESPONSES[_term_key(term)] for term in pair.terms)
        shear, volume = reference
        determinant = g1 * v2 - g2 * v1
        if abs(determinant) > 1e-9:
            first = (shear * v2 - g2 * volume) / determinant
            second = (g1 * volume - shear * v1) / determinant
            if first > 0 and second > 0:
                return math.log(first), math.log(second)
    return stiffness, stiffness


def _with_moduli(rng: random.Random, genome: Genome, moduli: tuple[float, float]) -> Genome:
    """``genome`` with its terms' log-moduli drawn around ``moduli``."""
    terms = tuple(
        replace(term, coefficient=Param("log", round(rng.gauss(modulus, PAIR_SPREAD), 4)))
        for term, modulus in zip(genome.terms, moduli, strict=True)
    )
    return replace(genome, terms=terms)


def _replacing(genome: Genome) -> Genome:
    """A plastic ``genome`` whose corrections start by replacing F (weight 1), as every
    textbook return does: an opening's small form is fitted from there first."""
    terms = tuple(replace(t, coefficient=replace(t.coefficient, raw=1.0)) for t in genome.terms)
    return replace(genome, terms=terms)


def _higher_start(rng: random.Random, genome: Genome) -> Genome | None:
    """``genome`` with its positive constants (log leaves) drawn from :data:`HIGHER_START`;
    None when it has none."""
    found = [(index, path, param) for index, path, param in params(genome)
             if path is not None and param.transform == "log"]  # fmt: skip
    for index, path, param in found:
        raw = round(rng.uniform(*HIGHER_START), 4)
        genome = with_param(genome, index, path, replace(param, raw=raw))
    return genome if found else None


def _fresh_weights(rng: random.Random, child: Genome, parents: tuple[Genome, ...]) -> Genome:
    """``child`` with a new starting weight for every term whose correction no parent has: a
    fitted weight belongs to its correction (a weight fitted near 0 for a poor correction
    would otherwise start, and often stay, the better one it became)."""
    known = {term.expr for parent in parents for term in parent.terms}
    terms = tuple(
        term
        if term.expr in known
        else replace(term, coefficient=random_coefficient(rng, "plastic"))
        for term in child.terms
    )
    return replace(child, terms=terms)


def _loss(value: float) -> float:
    """A NaN loss ranks last, as inf (an invalid parent)."""
    return math.inf if math.isnan(value) else value


def _tournament(rng: random.Random, pool: list[_Member], size: int) -> _Member:
    """The best of ``size`` members drawn without replacement (ties: the earlier one)."""
    drawn = sorted(rng.sample(range(len(pool)), min(size, len(pool))))
    return min((pool[i] for i in drawn), key=lambda member: member.loss)


def _answer(code: str, note: str) -> str:
    return (
        "### Analysis\n"
        f"Genetic programming over typed tensor blocks: {note}.\n\n"
        "### Code\n"
        f"```python\n{code}```\n"
    )
