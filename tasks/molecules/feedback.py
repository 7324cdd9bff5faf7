"""The feedback text a scored molecule gets (shown to the proposer in later prompts)."""

from __future__ import annotations

import numpy as np

from tasks.molecules.calibration import (
    PROPERTY_LABELS,
    QM9_STATISTICS,
    normalize,
    to_qm9_scale,
)
from tasks.molecules.geometry import Structure
from tasks.molecules.inner_loop import StepRecord, Trajectory
from tasks.molecules.xtb import HARTREE_IN_EV


def format_coordinates(xyz: np.ndarray, decimals: int = 3) -> str:
    """Rows ``[x, y, z]`` of a coordinate array as a python literal, one row per line."""
    rows = ",\n".join(
        "    [" + ", ".join(f"{v:.{decimals}f}" for v in row) + "]" for row in np.asarray(xyz)
    )
    return f"[\n{rows},\n]"


def frontier_values(record: StepRecord) -> dict[str, float]:
    """QM9-scale HOMO, LUMO and gap (Hartree) of a step."""
    return {
        "homo": float(to_qm9_scale("homo", record.homo)),
        "lumo": float(to_qm9_scale("lumo", record.lumo)),
        "gap": float(to_qm9_scale("gap", record.lumo - record.homo)),
    }


def normalized_values(record: StepRecord) -> dict[str, float]:
    """Normalized HOMO, LUMO and gap of a step."""
    return {p: float(normalize(p, v)) for p, v in frontier_values(record).items()}


def _state(prop: str, record: StepRecord) -> str:
    label = PROPERTY_LABELS[prop]
    qm9 = frontier_values(record)[prop]
    others = ", ".join(
        f"{PROPERTY_LABELS[p].split()[-1]} {v:+.3f}"
        for p, v in normalized_values(record).items()
        if p != prop
    )
    return (
        f"{record.property:+.3f} ({label} {qm9:+.4f} Ha = {qm9 * HARTREE_IN_EV:+.2f} eV on the "
        f"QM9 B3LYP scale; normalized {others})"
    )


def describe(smiles: str, structure: Structure, trajectory: Trajectory) -> str:
    """Feedback for a scored molecule: structure, target, property before and after, losses,
    and the optimized heavy-atom coordinates."""
    objective = trajectory.objective
    prop = objective.prop
    label = PROPERTY_LABELS[prop]
    stats = QM9_STATISTICS[prop]
    best = trajectory.best
    first, chosen = trajectory.records[0], trajectory.records[best]
    n_atoms = len(structure.numbers)
    lines = [f"Molecule: {smiles} ({structure.n_heavy} heavy atoms, {n_atoms} with hydrogens)."]
    if structure.source == "proposal":
        lines.append(
            f"3D structure: your coordinates with hydrogens added, relaxed with "
            f"{structure.force_field} (heavy atoms moved {structure.rmsd:.2f} A RMSD)."
        )
    else:
        lines.append("3D structure: " + structure.note)
    done = len(trajectory.records) - 1
    lines += [
        f"Target: normalized {label} = {objective.target:+.2f} (units of the QM9 standard "
        f"deviation {stats.std:.4f} Ha from the QM9 mean {stats.mean:+.4f} Ha).",
        f"{label} before optimization: {_state(prop, first)}.",
        f"{label} after {done} Adam steps on the atomic positions (best step {best}): "
        f"{_state(prop, chosen)}.",
    ]
    if trajectory.stopped:
        lines.append(f"Note: {trajectory.stopped}.")
    property_loss = trajectory.property_loss[best]
    conformer_loss = trajectory.conformer_loss[best]
    lines += [
        f"Property loss (squared distance to the target): {property_loss:.4f}",
        f"Conformer loss ({objective.strain_weight:g} per kcal/mol of strain; strain "
        f"{trajectory.strain[best]:.2f} kcal/mol above the run's lowest GFN1-xTB energy): "
        f"{conformer_loss:.4f}",
        f"Total loss: {property_loss + conformer_loss:.4f}",
        "Optimized heavy-atom coordinates (Angstrom, SMILES atom order):",
        format_coordinates(chosen.positions[: structure.n_heavy]),
    ]
    return "\n".join(lines)
