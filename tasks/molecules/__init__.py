"""Molecule design tasks (e)-(h): a SMILES plus heavy-atom coordinates whose HOMO, LUMO or gap,
on the normalized QM9 scale, hits a target.

The property is real quantum chemistry: GFN1-xTB through dxtb (differentiable, PyTorch), mapped
onto QM9's B3LYP scale by a linear calibration fitted on QM9 (``scripts/calibrate_qm9.py``). The
inner loop moves the atoms with Adam on the property, with an xTB strain penalty. Modules:

- ``solution``: reads SMILES and coordinates from the proposal text (``ast``, nothing executed)
- ``validation``: RDKit checks, each failure one feedback sentence
- ``geometry``: hydrogens, MMFF94/UFF relaxation, ETKDG fallback
- ``xtb``: dxtb single points, smooth HOMO/LUMO
- ``calibration``: QM9 statistics and the GFN1 -> B3LYP lines
- ``inner_loop``: Adam on positions, losses per step
- ``feedback``, ``evaluation``, ``prompt_text``, ``task``: the Task plugin

Importing this package (to list or describe tasks) loads neither torch, RDKit nor dxtb.
"""

from tasks.molecules.task import GapLowTask, GapTask, HomoTask, LumoTask, MoleculeTask

__all__ = ["GapLowTask", "GapTask", "HomoTask", "LumoTask", "MoleculeTask"]
