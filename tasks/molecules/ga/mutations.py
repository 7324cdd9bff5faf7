"""Graph mutations: each operator edits one atom, bond or ring of a sanitized molecule.

An operator takes the molecule and the random generator and returns the edited graph (not yet
sanitized; :func:`tasks.molecules.ga.graph.accept` judges it) or None when the molecule offers
no site for it. Hydrogens are implicit: they follow from the bonds after every edit, so an
operator needs a free hydrogen wherever it adds a bond.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from typing import TypeVar

from rdkit import Chem

from tasks.molecules.ga.graph import Limits, accept, editable

#: Elements an atom may become or be added as, with their weights and valences.
ELEMENTS: dict[str, tuple[float, int]] = {
    "C": (4.0, 4), "N": (2.0, 3), "O": (2.0, 2), "F": (0.5, 1), "S": (0.5, 2), "Cl": (0.5, 1),
}  # fmt: skip
#: Weights of a new bond's order (when the free hydrogens allow it).
ORDERS = {1: 0.8, 2: 0.15, 3: 0.05}
BOND_TYPES = {1: Chem.BondType.SINGLE, 2: Chem.BondType.DOUBLE, 3: Chem.BondType.TRIPLE}
#: Rings :func:`insert_ring` attaches, as SMILES.
RINGS = ("c1ccccc1", "c1ccncc1", "C1CCCCC1", "C1CCCC1", "c1ccoc1", "c1ccsc1", "c1cc[nH]c1")
#: Topological distances :func:`close_ring` bridges: new rings of five and six atoms.
RING_CLOSURES = (4, 5)

Operator = Callable[[Chem.Mol, random.Random], Chem.RWMol | None]
_Key = TypeVar("_Key")


def _pick(rng: random.Random, weights: dict[_Key, float]) -> _Key:
    keys = list(weights)
    return rng.choices(keys, weights=[weights[k] for k in keys])[0]


def _element(rng: random.Random, min_valence: int = 1, other_than: str = "") -> str | None:
    choices = {
        e: weight
        for e, (weight, valence) in ELEMENTS.items()
        if valence >= min_valence and e != other_than
    }
    return _pick(rng, choices) if choices else None


def _with_hydrogens(mol: Chem.Mol) -> list[int]:
    return [atom.GetIdx() for atom in mol.GetAtoms() if atom.GetTotalNumHs() > 0]


def _order(bond: Chem.Bond) -> int:
    return int(bond.GetBondTypeAsDouble())


def append_atom(mol: Chem.Mol, rng: random.Random) -> Chem.RWMol | None:
    """Bond a new atom to an atom with a free hydrogen (single, sometimes double or triple)."""
    sites = _with_hydrogens(mol)
    if not sites:
        return None
    site = rng.choice(sites)
    element = _element(rng)
    most = min(mol.GetAtomWithIdx(site).GetTotalNumHs(), ELEMENTS[element][1])
    order = _pick(rng, {k: w for k, w in ORDERS.items() if k <= most})
    rw = editable(mol)
    new = rw.AddAtom(Chem.Atom(element))
    rw.AddBond(site, new, BOND_TYPES[order])
    return rw


def insert_atom(mol: Chem.Mol, rng: random.Random) -> Chem.RWMol | None:
    """Put a new atom into a bond: ``A~B`` becomes ``A-X-B``."""
    if mol.GetNumBonds() == 0:
        return None
    rw = editable(mol)
    bond = rw.GetBondWithIdx(rng.randrange(rw.GetNumBonds()))
    a, b = bond.GetBeginAtomIdx(), bond.GetEndAtomIdx()
    rw.RemoveBond(a, b)
    new = rw.AddAtom(Chem.Atom(_element(rng, min_valence=2)))
    rw.AddBond(a, new, Chem.BondType.SINGLE)
    rw.AddBond(new, b, Chem.BondType.SINGLE)
    return rw


def delete_atom(mol: Chem.Mol, rng: random.Random) -> Chem.RWMol | None:
    """Remove a terminal atom, or a chain or ring atom whose two neighbours are then joined."""
    sites = [atom.GetIdx() for atom in mol.GetAtoms() if atom.GetDegree() in (1, 2)]
    if not sites:
        return None
    rw = editable(mol)
    site = rng.choice(sites)
    neighbours = [n.GetIdx() for n in rw.GetAtomWithIdx(site).GetNeighbors()]
    if len(neighbours) == 2 and rw.GetBondBetweenAtoms(*neighbours) is None:
        rw.AddBond(*neighbours, Chem.BondType.SINGLE)
    rw.RemoveAtom(site)
    return rw


def change_element(mol: Chem.Mol, rng: random.Random) -> Chem.RWMol | None:
    """Turn an uncharged atom into another element whose valence holds its bonds."""
    sites = [atom.GetIdx() for atom in mol.GetAtoms() if atom.GetFormalCharge() == 0]
    if not sites:
        return None
    rw = editable(mol)
    atom = rw.GetAtomWithIdx(rng.choice(sites))
    bonds = sum(_order(bond) for bond in atom.GetBonds())
    element = _element(rng, min_valence=bonds, other_than=atom.GetSymbol())
    if element is None:
        return None
    atom.SetAtomicNum(Chem.GetPeriodicTable().GetAtomicNumber(element))
    return rw


def change_bond_order(mol: Chem.Mol, rng: random.Random) -> Chem.RWMol | None:
    """Raise a bond's order by one (both atoms need a free hydrogen) or lower it by one."""
    rw = editable(mol)
    changes = []
    for bond in rw.GetBonds():
        order, ends = _order(bond), (bond.GetBeginAtom(), bond.GetEndAtom())
        if order < 3 and all(mol.GetAtomWithIdx(a.GetIdx()).GetTotalNumHs() for a in ends):
            changes.append((bond.GetIdx(), order + 1))
        if order > 1:
            changes.append((bond.GetIdx(), order - 1))
    if not changes:
        return None
    index, order = rng.choice(changes)
    rw.GetBondWithIdx(index).SetBondType(BOND_TYPES[order])
    return rw


def close_ring(mol: Chem.Mol, rng: random.Random) -> Chem.RWMol | None:
    """Bond two atoms with free hydrogens that are four or five bonds apart (a new 5/6-ring)."""
    sites = _with_hydrogens(mol)
    distance = Chem.GetDistanceMatrix(mol)
    pairs = [
        (a, b) for i, a in enumerate(sites) for b in sites[i + 1 :]
        if distance[a, b] in RING_CLOSURES
    ]  # fmt: skip
    if not pairs:
        return None
    rw = editable(mol)
    rw.AddBond(*rng.choice(pairs), Chem.BondType.SINGLE)
    return rw


def open_ring(mol: Chem.Mol, rng: random.Random) -> Chem.RWMol | None:
    """Remove one ring bond (the molecule stays in one piece)."""
    bonds = [bond.GetIdx() for bond in mol.GetBonds() if bond.IsInRing()]
    if not bonds:
        return None
    rw = editable(mol)
    bond = rw.GetBondWithIdx(rng.choice(bonds))
    rw.RemoveBond(bond.GetBeginAtomIdx(), bond.GetEndAtomIdx())
    return rw


def insert_ring(mol: Chem.Mol, rng: random.Random) -> Chem.RWMol | None:
    """Attach a small ring (benzene, pyridine, cyclohexane, a five-ring) by a single bond."""
    sites = _with_hydrogens(mol)
    if not sites:
        return None
    site = rng.choice(sites)
    ring = Chem.MolFromSmiles(rng.choice(RINGS))
    anchor = rng.choice(_with_hydrogens(ring))
    combined = Chem.CombineMols(mol, ring)
    Chem.SanitizeMol(combined)
    rw = editable(combined)
    rw.AddBond(site, mol.GetNumAtoms() + anchor, Chem.BondType.SINGLE)
    return rw


def delete_ring(mol: Chem.Mol, rng: random.Random) -> Chem.RWMol | None:
    """Remove the atoms only one ring holds; of what falls apart, keep the largest piece."""
    info = mol.GetRingInfo()
    own = [[i for i in ring if info.NumAtomRings(i) == 1] for ring in info.AtomRings()]
    own = [atoms for atoms in own if 0 < len(atoms) < mol.GetNumAtoms()]
    if not own:
        return None
    rw = editable(mol)
    remove_atoms(rw, rng.choice(own))
    pieces = Chem.GetMolFrags(rw)
    keep = max(range(len(pieces)), key=lambda k: len(pieces[k]))
    remove_atoms(rw, [i for k, piece in enumerate(pieces) if k != keep for i in piece])
    return rw


def remove_atoms(rw: Chem.RWMol, atoms: list[int] | tuple[int, ...]) -> None:
    """Remove ``atoms`` from ``rw`` in place; the others keep their relative order."""
    rw.BeginBatchEdit()
    for index in atoms:
        rw.RemoveAtom(index)
    rw.CommitBatchEdit()


MUTATIONS: dict[str, Operator] = {
    op.__name__: op
    for op in (
        append_atom, insert_atom, delete_atom, change_element, change_bond_order,
        close_ring, open_ring, insert_ring, delete_ring,
    )
}  # fmt: skip


def mutate(
    mol: Chem.Mol, rng: random.Random, limits: Limits, operator: str | None = None
) -> tuple[Chem.Mol | None, str]:
    """Apply one mutation (``operator``, or one drawn uniformly); the child and the name.

    The child is None when the operator found no site or the result failed the filters.
    """
    name = operator or rng.choice(list(MUTATIONS))
    edited = MUTATIONS[name](mol, rng)
    return (accept(edited, limits) if edited is not None else None), name
