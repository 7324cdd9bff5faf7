"""Heavy-atom coordinates for a child: an ETKDG conformer relaxed with MMFF94 (UFF as fallback)."""

from __future__ import annotations

from rdkit import Chem
from rdkit.Chem import AllChem
from rdkit.rdBase import BlockLogs

EMBED_TIMEOUT_S = 5
"""Seconds ETKDG may spend on one molecule before the child is given up."""


def heavy_coordinates(smiles: str, seed: int) -> list[list[float]] | None:
    """Coordinates (Angstrom) of the heavy atoms of ``smiles`` in SMILES order, or None.

    Hydrogens are added for the embedding and the force-field relaxation and dropped after;
    they come after the heavy atoms, so the first rows are the heavy atoms in the order the
    SMILES lists them (the order the task reads coordinates in). None when the molecule cannot
    be embedded.
    """
    mol = Chem.AddHs(Chem.MolFromSmiles(smiles))
    params = AllChem.ETKDGv3()
    params.randomSeed = seed & 0x7FFFFFFF
    params.timeout = EMBED_TIMEOUT_S
    with BlockLogs():
        if AllChem.EmbedMolecule(mol, params) != 0:
            return None
        if AllChem.MMFFHasAllMoleculeParams(mol):
            AllChem.MMFFOptimizeMolecule(mol, maxIters=1000)
        else:
            AllChem.UFFOptimizeMolecule(mol, maxIters=1000)
    positions = mol.GetConformer().GetPositions()[: mol.GetNumHeavyAtoms()]
    return positions.tolist()
