"""Molecular graphs for the GA operators: the editable form they change, and the filters that
turn an edited graph back into an accepted child (a canonical SMILES) or reject it."""

from __future__ import annotations

from dataclasses import dataclass

from rdkit import Chem
from rdkit.rdBase import BlockLogs

from tasks.molecules.constants import MAX_HEAVY_ATOMS, MIN_HEAVY_ATOMS
from tasks.molecules.validation import InvalidMolecule, check_molecule

#: Bonds that make a ring implausible: a double or triple bond in a 3- or 4-membered ring, a
#: triple bond or an allene in any ring (Jensen's ``ring_OK``, extended to triple bonds).
_STRAINED = [Chem.MolFromSmarts(s) for s in ("[r3,r4]=,#[r3,r4]", "*#@*", "[R]=[R]=[R]")]


@dataclass(frozen=True)
class Limits:
    """What a child must respect besides the task's own validation.

    Parameters
    ----------
    min_atoms : int
        Fewest heavy atoms (the task allows 8 to 40).
    max_atoms : int
        Most heavy atoms (30 keeps evaluations quick).
    max_ring : int
        Largest ring size (larger rings are rarely useful and embed poorly).
    """

    min_atoms: int = MIN_HEAVY_ATOMS
    max_atoms: int = 30
    max_ring: int = 7

    def __post_init__(self) -> None:
        if not MIN_HEAVY_ATOMS <= self.min_atoms <= self.max_atoms <= MAX_HEAVY_ATOMS:
            raise ValueError(
                f"need {MIN_HEAVY_ATOMS} <= min_atoms <= max_atoms <= {MAX_HEAVY_ATOMS} (the "
                f"task's limits), got min_atoms={self.min_atoms}, max_atoms={self.max_atoms}"
            )
        if self.max_ring < 3:
            raise ValueError(f"max_ring must be at least 3, got {self.max_ring}")


def editable(mol: Chem.Mol) -> Chem.RWMol:
    """A Kekulé copy of a sanitized ``mol`` without stereo, whose hydrogens follow the bonds.

    Explicit hydrogen counts (``[nH]``, ``[C@H]``) are dropped so that, after an edit, RDKit
    recomputes every atom's hydrogens from its default valence.
    """
    rw = Chem.RWMol(mol)
    Chem.RemoveStereochemistry(rw)
    Chem.Kekulize(rw, clearAromaticFlags=True)
    for atom in rw.GetAtoms():
        atom.SetNumExplicitHs(0)
        atom.SetNoImplicit(False)
        atom.SetNumRadicalElectrons(0)
    return rw


def canonical(mol: Chem.Mol) -> str:
    """Canonical SMILES of ``mol`` without stereo (how children and parents are compared)."""
    mol = Chem.Mol(mol)
    Chem.RemoveStereochemistry(mol)
    return Chem.MolToSmiles(mol)


def accept(edited: Chem.Mol, limits: Limits) -> Chem.Mol | None:
    """The sanitized child if it passes the task's validation and ``limits``, else None."""
    mol = Chem.Mol(edited)
    with BlockLogs():
        try:
            Chem.SanitizeMol(mol)
        except Exception:  # RDKit raises several exception types for a bad valence or ring
            return None
    try:
        mol = check_molecule(canonical(mol))
    except InvalidMolecule:
        return None
    return mol if _plausible(mol, limits) else None


def _plausible(mol: Chem.Mol, limits: Limits) -> bool:
    if not limits.min_atoms <= mol.GetNumAtoms() <= limits.max_atoms:
        return False
    if any(len(ring) > limits.max_ring for ring in mol.GetRingInfo().AtomRings()):
        return False
    if any(mol.HasSubstructMatch(pattern) for pattern in _STRAINED):
        return False
    return not any(_hypervalent_hydride(atom) for atom in mol.GetAtoms())


def _hypervalent_hydride(atom: Chem.Atom) -> bool:
    """An uncharged atom above its lowest valence that still carries hydrogens (``[SH4]``)."""
    lowest = Chem.GetPeriodicTable().GetValenceList(atom.GetAtomicNum())[0]
    return (
        atom.GetFormalCharge() == 0 and atom.GetTotalNumHs() > 0 and atom.GetTotalValence() > lowest
    )
