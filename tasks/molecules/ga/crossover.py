"""Crossover by fragment exchange (after Jensen 2019).

Each parent is cut in two, either at one acyclic bond or at two bonds of one ring; a piece of
the first parent and a piece of the second are joined where they were cut. A bond rejoined
gets the lower order of the two bonds cut there, so every atom's valence stays feasible and a
Kekulé double bond of two aromatic rings survives the exchange.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from dataclasses import dataclass

from rdkit import Chem

from tasks.molecules.ga.graph import Limits, accept, editable
from tasks.molecules.ga.mutations import BOND_TYPES, remove_atoms


@dataclass(frozen=True)
class Piece:
    """One side of a cut parent: its Kekulé graph, the atoms that lost a bond and the orders."""

    mol: Chem.RWMol
    ends: tuple[int, ...]
    orders: tuple[int, ...]


def _cut(mol: Chem.Mol, bonds: list[int], rng: random.Random) -> Piece | None:
    """Remove ``bonds`` (one acyclic or two of one ring); if two pieces result, one at random."""
    rw = editable(mol)
    cuts = []
    for index in bonds:
        bond = rw.GetBondWithIdx(index)
        cuts.append((bond.GetBeginAtomIdx(), bond.GetEndAtomIdx(), int(bond.GetBondTypeAsDouble())))
    for a, b, _ in cuts:
        rw.RemoveBond(a, b)
    pieces = Chem.GetMolFrags(rw)
    if len(pieces) != 2:
        return None
    kept = sorted(rng.choice(pieces))  # every cut bond joined the two pieces: none was a bridge
    remove_atoms(rw, [i for i in range(rw.GetNumAtoms()) if i not in kept])
    ends = tuple(kept.index(a if a in kept else b) for a, b, _ in cuts)
    return Piece(rw, ends, tuple(order for _, _, order in cuts))


def cut_acyclic(mol: Chem.Mol, rng: random.Random) -> Piece | None:
    """A piece of ``mol`` cut at one bond outside any ring (None if there is none)."""
    bonds = [bond.GetIdx() for bond in mol.GetBonds() if not bond.IsInRing()]
    return _cut(mol, [rng.choice(bonds)], rng) if bonds else None


def cut_ring(mol: Chem.Mol, rng: random.Random) -> Piece | None:
    """A piece of ``mol`` cut at two bonds of one ring (None if that leaves it in one piece)."""
    rings = mol.GetRingInfo().BondRings()
    return _cut(mol, rng.sample(list(rng.choice(rings)), 2), rng) if rings else None


def join(first: Piece, second: Piece, rng: random.Random) -> Chem.RWMol | None:
    """Bond the cut ends of two pieces pairwise (in random orientation for two ends)."""
    rw = Chem.RWMol(Chem.CombineMols(first.mol, second.mol))
    offset = first.mol.GetNumAtoms()
    partners = list(zip(second.ends, second.orders, strict=True))
    if rng.random() < 0.5:
        partners.reverse()
    for (a, order_a), (b, order_b) in zip(
        zip(first.ends, first.orders, strict=True), partners, strict=True
    ):
        if rw.GetBondBetweenAtoms(a, offset + b) is not None:
            return None
        rw.AddBond(a, offset + b, BOND_TYPES[min(order_a, order_b)])
    return rw


CUTS: dict[str, Callable[[Chem.Mol, random.Random], Piece | None]] = {
    "ring_crossover": cut_ring,
    "acyclic_crossover": cut_acyclic,
}


def crossover(
    first: Chem.Mol, second: Chem.Mol, rng: random.Random, limits: Limits, kind: str | None = None
) -> tuple[Chem.Mol | None, str]:
    """A child of two parents and the crossover's name (a key of :data:`CUTS`).

    ``kind`` None cuts at rings half of the time when both parents have one. The child is None
    when a parent could not be cut that way or the joined graph failed the filters.
    """
    if kind is None:
        rings = first.GetRingInfo().NumRings() and second.GetRingInfo().NumRings()
        kind = "ring_crossover" if rings and rng.random() < 0.5 else "acyclic_crossover"
    cut = CUTS[kind]
    pieces = cut(first, rng), cut(second, rng)
    if pieces[0] is None or pieces[1] is None:
        return None, kind
    joined = join(pieces[0], pieces[1], rng)
    return (accept(joined, limits) if joined is not None else None), kind
