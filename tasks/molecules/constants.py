"""Limits and defaults shared by the molecule tasks (kept free of heavy imports)."""

MIN_HEAVY_ATOMS = 8
MAX_HEAVY_ATOMS = 40
"""Larger molecules are refused to keep an evaluation within its time budget: with the default
30 steps on one core, 37 heavy atoms (68 atoms) take about 14 s, 45 heavy atoms (78) about 20 s."""

MIN_SEPARATION = 0.5
"""Two heavy atoms closer than this (Angstrom) overlap."""

SUPPORTED_ELEMENTS = ("B", "C", "N", "O", "F", "Si", "P", "S", "Cl", "Se", "Br", "I")
"""Heavy elements accepted: covered by GFN1-xTB and by MMFF94 or UFF. Metals and noble gases
are refused; the QM9 calibration itself was fitted on H, C, N, O and F only."""

DEFAULT_STEPS = 30
"""Adam steps of the inner loop."""

DEFAULT_LEARNING_RATE = 0.01
"""Adam step size in Angstrom."""

DEFAULT_STRAIN_WEIGHT = 0.3
"""Conformer-loss weight per kcal/mol of strain: one kcal/mol costs 0.3, as much as a property
0.55 QM9 standard deviations off its target. At 0.1, runs aimed at far targets reached 20-30
kcal/mol of strain in 30 steps; at 0.3 a few kcal/mol."""
