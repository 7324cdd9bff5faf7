"""Task-specific prompt text of the molecule-design tasks (our wording).

The structure follows the paper's molecule prompts: who the model is, what is designed and how a
design is scored, the code skeleton of a proposal, and the rules a proposal must obey.
"""

from __future__ import annotations

from tasks.molecules.calibration import PROPERTY_LABELS, QM9_STATISTICS
from tasks.molecules.constants import MAX_HEAVY_ATOMS, MIN_HEAVY_ATOMS, SUPPORTED_ELEMENTS

ROLE = (
    "You are an expert in organic chemistry, quantum chemistry and molecule design, fluent in "
    "the SMILES notation and in building 3D molecular geometries, helping to design molecules "
    "with prescribed frontier-orbital energies."
)

_CONTEXT = (
    "Design one neutral, closed-shell molecule, given as a SMILES string plus 3D coordinates of "
    "its heavy atoms, whose {label} reaches {target:g} on the normalized QM9 scale. The scale "
    "is the B3LYP/6-31G(2df,p) value of the QM9 data set minus the QM9 mean ({mean:+.4f} Ha), "
    "divided by the QM9 standard deviation ({std:.4f} Ha): 0 is a typical small organic "
    "molecule, -2 lies two standard deviations below it.\n"
    "How a proposal is scored: hydrogens are added to your heavy atoms and the structure is "
    "relaxed with the MMFF94 force field (UFF where MMFF94 lacks parameters) starting from your "
    "coordinates; coordinates that do not reproduce the SMILES bonds or stereochemistry are "
    "replaced by a generated conformer. "
    "GFN1-xTB computes the orbital energies, mapped linearly onto the QM9 B3LYP scale. Then "
    "{steps} Adam steps move all atoms to bring the property towards the target while the rise "
    "of the xTB energy (strain) is penalized. The loss is the squared distance of the "
    "normalized property to the target plus {weight:g} per kcal/mol of strain; lower is "
    "better. Geometry changes move the property only a little: the molecular structure "
    "(the SMILES) decides most of it."
)

TEMPLATE = """SMILES: str = "..."  # N heavy atoms

coordinates: list[list[float]] = [  # (N, 3) heavy-atom positions in Angstrom, SMILES order
    [x, y, z],  # atom 0: element
    # ... one row per heavy atom
]
"""

REQUIREMENTS = f"""\
Code rules:
1. Python, exactly two top-level assignments of literal values: `SMILES` (a string) and
   `coordinates` (a list of [x, y, z] rows, Angstrom). Nothing is executed: no imports, no
   function calls, no variables, no arithmetic.
2. `SMILES` must be valid for RDKit and describe a single neutral, closed-shell molecule: one
   fragment (no '.'), no net charge, no radicals, hydrogens implicit (no [H] atoms), elements
   from {", ".join(SUPPORTED_ELEMENTS)} only, and {MIN_HEAVY_ATOMS} to {MAX_HEAVY_ATOMS} heavy
   atoms. Diverse elements and ring systems are welcome.
3. `coordinates` has exactly one row per heavy atom, in the order the atoms are written in the
   SMILES, without hydrogens. Count the heavy atoms of your SMILES one by one and state the
   count and the shape (N, 3) in comments, as in the template.
4. Give a realistic geometry: bond lengths near 1.2-1.55 A (C-S 1.8, C-Cl 1.75, C-Br 1.9,
   C-I 2.1), angles matching each atom's hybridization, planar aromatic rings, and
   stereocenters as written in the SMILES. Rows must be distinct: atoms closer than 0.5 A are
   rejected.
5. The SMILES is the part that the inner optimization cannot change: propose a SMILES that
   differs from every earlier one, to explore new structures.
"""


def context(prop: str, target: float, steps: int, strain_weight: float) -> str:
    """The context paragraph of one task."""
    stats = QM9_STATISTICS[prop]
    return _CONTEXT.format(
        label=PROPERTY_LABELS[prop],
        target=target,
        mean=stats.mean,
        std=stats.std,
        steps=steps,
        weight=strain_weight,
    )
