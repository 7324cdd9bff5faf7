"""Chemical validation of a proposal with RDKit; every failure is one sentence of feedback."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from rdkit import Chem, RDLogger

from tasks.molecules.constants import (
    MAX_HEAVY_ATOMS,
    MIN_HEAVY_ATOMS,
    MIN_SEPARATION,
    SUPPORTED_ELEMENTS,
)
from tasks.molecules.solution import Proposal


class InvalidMolecule(ValueError):
    """The proposal is chemically unusable; the message is one-line feedback."""


@dataclass
class CheckedMolecule:
    """A validated proposal: the RDKit molecule (heavy atoms, SMILES order) and its coordinates."""

    smiles: str
    mol: Chem.Mol
    coordinates: np.ndarray

    @property
    def n_heavy(self) -> int:
        """Number of heavy atoms."""
        return self.mol.GetNumAtoms()


def _parse_smiles(smiles: str) -> Chem.Mol:
    RDLogger.DisableLog("rdApp.*")
    try:
        mol = Chem.MolFromSmiles(smiles, sanitize=False)
        if mol is None:
            raise InvalidMolecule(f"the SMILES {smiles!r} could not be parsed (syntax error)")
        try:
            Chem.SanitizeMol(mol)
        except Exception as error:  # RDKit raises several exception types here
            message = str(error).strip().splitlines()[0] if str(error).strip() else "unknown"
            raise InvalidMolecule(
                f"the SMILES {smiles!r} is not a valid molecule: {message}"
            ) from None
        try:
            mol = Chem.RemoveHs(mol)
            # Stereo perception (part of MolFromSmiles, not of SanitizeMol): E/Z labels on
            # double bonds, and chiral tags cleared where an atom is no stereocenter.
            Chem.AssignStereochemistry(mol, cleanIt=True, force=True)
        except Exception as error:
            raise InvalidMolecule(f"the SMILES {smiles!r} is not usable: {error}") from None
    finally:
        RDLogger.EnableLog("rdApp.*")
    return mol


def check_molecule(smiles: str) -> Chem.Mol:
    """Parse and check the SMILES alone (everything but the coordinates).

    Raises
    ------
    InvalidMolecule
        Unparsable or unsanitizable SMILES, several fragments, explicit or unsupported atoms,
        radicals, a net charge, or too few or too many heavy atoms.
    """
    mol = _parse_smiles(smiles)
    if mol.GetNumAtoms() == 0:
        raise InvalidMolecule("the SMILES contains no atoms")
    fragments = len(Chem.GetMolFrags(mol))
    if fragments > 1:
        raise InvalidMolecule(
            f"the SMILES has {fragments} disconnected fragments ('.'); propose one connected "
            "molecule"
        )
    symbols = [atom.GetSymbol() for atom in mol.GetAtoms()]
    if "H" in symbols:
        raise InvalidMolecule(
            "the SMILES keeps explicit hydrogen atoms; write hydrogens implicitly so that the "
            "coordinates list heavy atoms only"
        )
    unsupported = sorted({s for s in symbols if s not in SUPPORTED_ELEMENTS})
    if unsupported:
        raise InvalidMolecule(
            f"element(s) {', '.join(unsupported)} are not supported; use only "
            f"{', '.join(SUPPORTED_ELEMENTS)} (plus implicit H)"
        )
    radicals = [
        f"{atom.GetSymbol()}{atom.GetIdx()}"
        for atom in mol.GetAtoms()
        if atom.GetNumRadicalElectrons() > 0
    ]
    if radicals:
        raise InvalidMolecule(
            f"the molecule is a radical (unpaired electrons on atom(s) {', '.join(radicals)}, "
            "0-based); propose a closed-shell molecule with complete valences"
        )
    charge = Chem.GetFormalCharge(mol)
    if charge != 0:
        raise InvalidMolecule(
            f"the molecule has a net charge of {charge:+d}; propose a neutral molecule"
        )
    n = mol.GetNumAtoms()
    if n < MIN_HEAVY_ATOMS:
        raise InvalidMolecule(
            f"the molecule has {n} heavy atoms; at least {MIN_HEAVY_ATOMS} are required"
        )
    if n > MAX_HEAVY_ATOMS:
        raise InvalidMolecule(
            f"the molecule has {n} heavy atoms; at most {MAX_HEAVY_ATOMS} are allowed"
        )
    return mol


def check_coordinates(mol: Chem.Mol, coordinates: list[list[float]]) -> np.ndarray:
    """Check the coordinate rows against the molecule; return them as an ``(N, 3)`` array.

    Raises
    ------
    InvalidMolecule
        Wrong number of rows, non-finite values, or overlapping atoms.
    """
    n = mol.GetNumAtoms()
    if len(coordinates) != n:
        raise InvalidMolecule(
            f"`coordinates` has {len(coordinates)} rows but the SMILES has {n} heavy atoms; "
            "give one [x, y, z] row per heavy atom, in SMILES order, without hydrogens"
        )
    xyz = np.asarray(coordinates, dtype=np.float64)
    if not np.isfinite(xyz).all():
        bad = int(np.argwhere(~np.isfinite(xyz))[0, 0])
        raise InvalidMolecule(f"`coordinates` row {bad} is not finite")
    distances = np.linalg.norm(xyz[:, None, :] - xyz[None, :, :], axis=-1)
    distances[np.diag_indices(n)] = math.inf
    i, j = np.unravel_index(int(np.argmin(distances)), distances.shape)
    if distances[i, j] < MIN_SEPARATION:
        a, b = sorted((int(i), int(j)))
        raise InvalidMolecule(
            f"atoms {a} and {b} overlap ({distances[i, j]:.2f} A apart; at least "
            f"{MIN_SEPARATION} A required)"
        )
    return xyz


def check_proposal(proposal: Proposal) -> CheckedMolecule:
    """Validate SMILES and coordinates together.

    Raises
    ------
    InvalidMolecule
        See :func:`check_molecule` and :func:`check_coordinates`.
    """
    mol = check_molecule(proposal.smiles)
    xyz = check_coordinates(mol, proposal.coordinates)
    return CheckedMolecule(smiles=Chem.MolToSmiles(mol), mol=mol, coordinates=xyz)
