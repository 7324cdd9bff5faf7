"""The molecule tasks' built-in proposer: a graph-based GA over the search's top-K parents."""

from __future__ import annotations

import math
import random
from collections.abc import Sequence
from dataclasses import dataclass

from rdkit import Chem

from sga_agent.task import Parent
from tasks.molecules.ga.conformer import heavy_coordinates
from tasks.molecules.ga.crossover import crossover
from tasks.molecules.ga.graph import Limits, canonical
from tasks.molecules.ga.mutations import mutate
from tasks.molecules.solution import ProposalError, format_solution, parse_solution
from tasks.molecules.validation import InvalidMolecule, check_molecule, check_proposal

EXPLOIT_TEMPERATURE = 0.5
"""At or below this temperature: single mutations, mostly of the best parent."""
EXPLORE_TEMPERATURE = 1.0
"""At or above this temperature: crossover for half the children, up to three mutations, and
parents drawn nearly uniformly."""


@dataclass(frozen=True)
class _Member:
    mol: Chem.Mol
    label: str


class GraphGAProposer:
    """Children of the top-K parents by graph mutations and crossover, with ETKDG coordinates.

    Each child passes the task's validation and the :class:`~tasks.molecules.ga.graph.Limits`,
    and differs (as a stereo-free canonical SMILES) from every parent, from the seed molecule
    and from the other children.

    Parameters
    ----------
    seed_solution : str
        The task's seed solution. Its molecule is the parent when no given parent can be read,
        and its mutations fill the batch when the parents yield too few children.
    limits : Limits, optional
        Size and ring limits of a child; default ``Limits()`` (8 to 30 heavy atoms).
    attempts_per_child : int
        Tries per requested child, for the parents and again for the seed fill (default 30).
    """

    name = "builtin:ga"

    def __init__(
        self, seed_solution: str, limits: Limits | None = None, attempts_per_child: int = 30
    ) -> None:
        if attempts_per_child < 1:
            raise ValueError(f"attempts_per_child must be at least 1, got {attempts_per_child}")
        self.seed_solution = seed_solution
        self.limits = limits or Limits()
        self.attempts_per_child = attempts_per_child

    def propose_from(
        self, parents: Sequence[Parent], temperature: float, n: int, seed: int
    ) -> list[str]:
        """Up to ``n`` answers, each with one ```python block (SMILES and coordinates).

        Fewer than ``n`` only when neither the parents nor the seed molecule yield enough
        distinct valid children within the attempts.
        """
        rng = random.Random(seed)
        pool = _members(parents)
        fill = _members([Parent(self.seed_solution, math.inf)], "the seed molecule")
        taken = {canonical(member.mol) for member in pool + fill}
        answers: list[str] = []
        for source in (pool or fill, fill):
            for _ in range(self.attempts_per_child * n if source else 0):
                if len(answers) >= n:
                    return answers
                child, steps = self._breed(source, temperature, rng)
                smiles = canonical(child) if child is not None else None
                if smiles is None or smiles in taken:
                    continue
                coordinates = heavy_coordinates(smiles, rng.getrandbits(31))
                code = format_solution(smiles, coordinates) if coordinates else None
                if code is None or not _valid(code):
                    continue
                taken.add(smiles)
                answers.append(_answer(code, steps, temperature))
        return answers

    def _breed(
        self, pool: list[_Member], temperature: float, rng: random.Random
    ) -> tuple[Chem.Mol | None, list[str]]:
        """A child (None if an operator failed) and the steps that made it."""
        bold = boldness(temperature)
        scale = 0.7 + bold * len(pool)
        weights = [math.exp(-rank / scale) for rank in range(len(pool))]
        extra = sum(rng.random() < 0.5 * bold for _ in range(2))
        first = rng.choices(range(len(pool)), weights=weights)[0]
        if len(pool) > 1 and rng.random() < 0.5 * bold:
            others = [i for i in range(len(pool)) if i != first]
            second = rng.choices(others, weights=[weights[i] for i in others])[0]
            child, kind = crossover(pool[first].mol, pool[second].mol, rng, self.limits)
            steps = [f"{kind} of {pool[first].label} and {pool[second].label}"]
            mutations = extra
        else:
            child, steps, mutations = pool[first].mol, [pool[first].label], 1 + extra
        for _ in range(mutations):
            if child is None:
                break
            child, operator = mutate(child, rng, self.limits)
            steps.append(operator)
        return child, steps


def boldness(temperature: float) -> float:
    """0 at the exploit temperature (or below), 1 at the explore temperature (or above)."""
    span = EXPLORE_TEMPERATURE - EXPLOIT_TEMPERATURE
    return min(max((temperature - EXPLOIT_TEMPERATURE) / span, 0.0), 1.0)


def _members(parents: Sequence[Parent], label: str = "") -> list[_Member]:
    """The readable, distinct parent molecules, best (lowest loss) first."""
    ranked = sorted(parents, key=lambda p: math.inf if math.isnan(p.loss) else p.loss)
    members: list[_Member] = []
    seen: set[str] = set()
    for parent in ranked:
        try:
            mol = check_molecule(parse_solution(parent.code).smiles)
        except (ProposalError, InvalidMolecule):
            continue
        if canonical(mol) not in seen:
            seen.add(canonical(mol))
            text = label or f"parent {len(members) + 1} (loss {parent.loss:.4g})"
            members.append(_Member(mol, text))
    return members


def _valid(code: str) -> bool:
    """Whether the task reads ``code`` as a valid proposal (SMILES and coordinates)."""
    try:
        check_proposal(parse_solution(code))
    except (ProposalError, InvalidMolecule):
        return False
    return True


def _answer(code: str, steps: list[str], temperature: float) -> str:
    return (
        "### Analysis\n"
        f"Graph GA (builtin:ga) at temperature {temperature:g}: {' -> '.join(steps)}.\n\n"
        f"### Code\n```python\n{code}```\n"
    )
