"""From proposed heavy-atom coordinates to a full, relaxed 3D structure with hydrogens.

1. Hydrogens are placed at the proposed heavy-atom geometry (RDKit ``AddHs(addCoords=True)``).
2. MMFF94 (UFF where MMFF94 lacks parameters) relaxes the hydrogens with the heavy atoms fixed,
   then everything with the heavy atoms restrained to the proposal (flat-bottomed harmonic
   restraints), then everything freely, so that the structure ends at the force field's local
   minimum nearest the proposed conformation. The free stage makes the reference energy of the
   inner loop's strain penalty a relaxed one: a strained proposal gains no energy budget.
3. The result is checked: bonds inferred from interatomic distances must be the SMILES bonds,
   stereocenters and double bonds given in the SMILES must be reproduced, and the heavy atoms
   must stay within :data:`MAX_RMSD` of the proposal (after optimal superposition). If any check
   fails, the proposal is unusable and an ETKDG conformer relaxed with the same force field
   replaces it; the structure records why.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from rdkit import Chem, RDLogger
from rdkit.Chem import AllChem
from rdkit.Chem.rdchem import BondStereo, ChiralType
from rdkit.Geometry import Point3D

from tasks.molecules.validation import CheckedMolecule, InvalidMolecule

MAX_RMSD = 1.5
"""Largest heavy-atom RMSD (Angstrom) between a proposal and its relaxed structure."""

RESTRAINT_SLACK = 0.3
"""Heavy atoms move freely within this distance (Angstrom) of the proposal in the restrained
stage; beyond it a harmonic restraint applies."""

RESTRAINT_FORCE = 100.0
"""Force constant of the restraints, kcal/mol/A^2."""

BOND_TOLERANCE = 1.3
"""Two atoms are taken as bonded when closer than this factor times their covalent radii sum."""


@dataclass
class Structure:
    """A molecule with explicit hydrogens and one relaxed conformer.

    Heavy atoms come first, in SMILES order; ``positions`` are in Angstrom.
    """

    mol: Chem.Mol
    numbers: np.ndarray
    positions: np.ndarray
    n_heavy: int
    force_field: str
    source: str
    note: str = ""
    rmsd: float | None = None

    @property
    def heavy_positions(self) -> np.ndarray:
        """Heavy-atom coordinates ``(n_heavy, 3)`` in Angstrom."""
        return self.positions[: self.n_heavy]


def _force_field_name(mol: Chem.Mol) -> str:
    if AllChem.MMFFHasAllMoleculeParams(mol):
        return "MMFF94"
    if AllChem.UFFHasAllMoleculeParams(mol):
        return "UFF"
    raise InvalidMolecule(
        "no force field (MMFF94 or UFF) has parameters for this molecule's atom types"
    )


def _force_field(mol: Chem.Mol, name: str) -> object:
    if name == "MMFF94":
        props = AllChem.MMFFGetMoleculeProperties(mol)
        return AllChem.MMFFGetMoleculeForceField(mol, props)
    return AllChem.UFFGetMoleculeForceField(mol)


def _restrain(ff: object, name: str, index: int, slack: float, force: float) -> None:
    if name == "MMFF94":
        ff.MMFFAddPositionConstraint(index, slack, force)
    else:
        ff.UFFAddPositionConstraint(index, slack, force)


def relax(mol: Chem.Mol, name: str, heavy: int, stages: tuple[str, ...]) -> None:
    """Minimize ``mol``'s conformer in place through ``stages`` ("fixed", "restrained", "free")."""
    for stage in stages:
        ff = _force_field(mol, name)
        if ff is None:
            raise InvalidMolecule("the force field could not be set up for this molecule")
        for i in range(heavy):
            if stage == "fixed":
                ff.AddFixedPoint(i)
            elif stage == "restrained":
                _restrain(ff, name, i, RESTRAINT_SLACK, RESTRAINT_FORCE)
        ff.Initialize()
        ff.Minimize(maxIts=2000 if stage == "free" else 500)


def inferred_bonds(numbers: np.ndarray, positions: np.ndarray) -> set[tuple[int, int]]:
    """Atom pairs closer than :data:`BOND_TOLERANCE` times the sum of their covalent radii."""
    table = Chem.GetPeriodicTable()
    radii = np.array([table.GetRcovalent(int(z)) for z in numbers])
    distance = np.linalg.norm(positions[:, None] - positions[None, :], axis=-1)
    limit = BOND_TOLERANCE * (radii[:, None] + radii[None, :])
    i, j = np.nonzero(np.triu(distance < limit, k=1))
    return set(zip(i.tolist(), j.tolist(), strict=True))


def graph_bonds(mol: Chem.Mol) -> set[tuple[int, int]]:
    """Bonded atom pairs of ``mol`` (smaller index first)."""
    return {
        (min(b.GetBeginAtomIdx(), b.GetEndAtomIdx()), max(b.GetBeginAtomIdx(), b.GetEndAtomIdx()))
        for b in mol.GetBonds()
    }


def stereo_matches(reference: Chem.Mol, mol_h: Chem.Mol) -> bool:
    """Whether the 3D structure reproduces the stereo given in ``reference`` (heavy atoms)."""
    wanted_atoms = {
        a.GetIdx() for a in reference.GetAtoms() if a.GetChiralTag() != ChiralType.CHI_UNSPECIFIED
    }
    wanted_bonds = {
        b.GetIdx() for b in reference.GetBonds() if b.GetStereo() != BondStereo.STEREONONE
    }
    if not wanted_atoms and not wanted_bonds:
        return True
    built = Chem.Mol(mol_h)
    Chem.AssignStereochemistryFrom3D(built)
    built = Chem.RemoveHs(built)
    for atom in built.GetAtoms():
        if atom.GetIdx() not in wanted_atoms:
            atom.SetChiralTag(ChiralType.CHI_UNSPECIFIED)
    for bond in built.GetBonds():
        if bond.GetIdx() not in wanted_bonds:
            bond.SetStereo(BondStereo.STEREONONE)
    Chem.AssignStereochemistry(built, cleanIt=True, force=True)
    return Chem.MolToSmiles(built) == Chem.MolToSmiles(reference)


def kabsch_rmsd(a: np.ndarray, b: np.ndarray) -> float:
    """RMSD between two ``(n, 3)`` point sets after optimal rotation and translation."""
    a = a - a.mean(axis=0)
    b = b - b.mean(axis=0)
    u, _, vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(u @ vt))
    rotation = u @ np.diag([1.0, 1.0, d]) @ vt
    return float(np.sqrt(np.mean(np.sum((a @ rotation - b) ** 2, axis=1))))


def _with_coordinates(mol: Chem.Mol, xyz: np.ndarray) -> Chem.Mol:
    mol = Chem.Mol(mol)
    mol.RemoveAllConformers()
    conformer = Chem.Conformer(mol.GetNumAtoms())
    for i, (x, y, z) in enumerate(xyz.tolist()):
        conformer.SetAtomPosition(i, Point3D(x, y, z))
    mol.AddConformer(conformer, assignId=True)
    return mol


def _problem(checked: CheckedMolecule, mol_h: Chem.Mol) -> tuple[str | None, float]:
    """Why the relaxed proposal is unusable (None if usable) and its heavy-atom RMSD."""
    positions = mol_h.GetConformer().GetPositions()
    if not np.isfinite(positions).all():
        return "the force-field relaxation diverged", float("nan")
    n = checked.n_heavy
    rmsd = kabsch_rmsd(checked.coordinates, positions[:n])
    numbers = np.array([a.GetAtomicNum() for a in mol_h.GetAtoms()])
    found, expected = inferred_bonds(numbers, positions), graph_bonds(mol_h)
    if found != expected:
        extra, missing = sorted(found - expected), sorted(expected - found)
        parts = []
        if missing:
            parts.append(f"bond(s) {', '.join(f'{i}-{j}' for i, j in missing[:3])} stretched apart")
        if extra:
            parts.append(f"atoms {', '.join(f'{i}-{j}' for i, j in extra[:3])} too close")
        return "after relaxation " + " and ".join(parts) + " (0-based, H after heavy)", rmsd
    if not stereo_matches(checked.mol, mol_h):
        return "the coordinates do not reproduce the stereochemistry of the SMILES", rmsd
    if rmsd > MAX_RMSD:
        return f"relaxation moved the heavy atoms {rmsd:.2f} A RMSD from the proposal", rmsd
    return None, rmsd


def from_proposal(checked: CheckedMolecule, name: str | None = None) -> tuple[Structure, str]:
    """Relax the proposal; returns the structure and the reason it is unusable ("" if usable)."""
    mol = _with_coordinates(checked.mol, checked.coordinates)
    mol_h = Chem.AddHs(mol, addCoords=True)
    name = name or _force_field_name(mol_h)
    relax(mol_h, name, checked.n_heavy, ("fixed", "restrained", "free"))
    problem, rmsd = _problem(checked, mol_h)
    return _structure(mol_h, checked.n_heavy, name, "proposal", rmsd=rmsd), problem or ""


def from_etkdg(checked: CheckedMolecule, seed: int, name: str | None = None) -> Structure:
    """An ETKDG conformer relaxed with the force field (independent of the proposal)."""
    mol_h = Chem.AddHs(checked.mol)
    name = name or _force_field_name(mol_h)
    params = AllChem.ETKDGv3()
    params.randomSeed = int(seed) & 0x7FFFFFFF
    if AllChem.EmbedMolecule(mol_h, params) != 0:
        params.useRandomCoords = True
        if AllChem.EmbedMolecule(mol_h, params) != 0:
            raise InvalidMolecule("RDKit could not embed a 3D structure for this molecule")
    relax(mol_h, name, checked.n_heavy, ("free",))
    positions = mol_h.GetConformer().GetPositions()
    rmsd = kabsch_rmsd(checked.coordinates, positions[: checked.n_heavy])
    return _structure(mol_h, checked.n_heavy, name, "ETKDG", rmsd=rmsd)


def _structure(mol_h: Chem.Mol, n_heavy: int, name: str, source: str, rmsd: float) -> Structure:
    return Structure(
        mol=mol_h,
        numbers=np.array([a.GetAtomicNum() for a in mol_h.GetAtoms()]),
        positions=mol_h.GetConformer().GetPositions(),
        n_heavy=n_heavy,
        force_field=name,
        source=source,
        rmsd=rmsd,
    )


def build_structure(checked: CheckedMolecule, seed: int = 0) -> Structure:
    """The relaxed proposal, or an ETKDG conformer (with a note saying why) if it is unusable.

    Raises
    ------
    InvalidMolecule
        No force field covers the molecule, or no 3D structure could be built at all.
    """
    RDLogger.DisableLog("rdApp.*")
    try:
        mol_h = Chem.AddHs(checked.mol)
        name = _force_field_name(mol_h)
        try:
            structure, problem = from_proposal(checked, name)
        except (RuntimeError, ValueError) as error:
            if isinstance(error, InvalidMolecule):
                raise
            structure, problem = None, f"RDKit failed on the proposed geometry ({error})"
        if not problem and structure is not None:
            return structure
        fallback = from_etkdg(checked, seed, name)
        fallback.note = (
            f"Your coordinates were not usable ({problem}); an RDKit ETKDG conformer relaxed "
            f"with {name} was used instead."
        )
        return fallback
    finally:
        RDLogger.EnableLog("rdApp.*")
