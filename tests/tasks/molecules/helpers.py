"""Shared helpers of the molecule-task tests."""

from __future__ import annotations

import numpy as np
from rdkit import Chem
from rdkit.Chem import AllChem

from sga_agent.task import Evaluation, EvaluationSettings, Task
from tasks.molecules.solution import format_solution


def conformer(smiles: str, seed: int = 7) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(atomic numbers with H, all positions in Angstrom, heavy-atom positions) of an MMFF
    conformer of ``smiles``; heavy atoms first, in SMILES order."""
    mol = Chem.AddHs(Chem.MolFromSmiles(smiles))
    assert AllChem.EmbedMolecule(mol, randomSeed=seed) == 0
    AllChem.MMFFOptimizeMolecule(mol)
    positions = mol.GetConformer().GetPositions()
    numbers = np.array([a.GetAtomicNum() for a in mol.GetAtoms()])
    return numbers, positions, positions[: mol.GetNumHeavyAtoms()]


def solution_for(smiles: str, seed: int = 7) -> str:
    """Solution text with a sensible conformer of ``smiles``."""
    return format_solution(smiles, conformer(smiles, seed)[2].tolist())


def score(task: Task, solution: str, settings: EvaluationSettings) -> Evaluation:
    """``solution`` captured and scored in this process, the two steps the sandbox runs apart."""
    return task.evaluate(task.capture(solution), settings)
