"""What the molecule tasks add to a run's facts and report: each top molecule's property back
on the QM9 scale (Hartree, eV) and its distance to the target, as a table in the summary, and
2D depictions of the top molecules.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from sga_agent.task import DPI, CandidateRecord, Image, ReportView, Section, Table, Text
from tasks.molecules.calibration import PROPERTY_LABELS, QM9_STATISTICS

LOSS_LABEL = "loss (dimensionless, normalised property)"
HARTREE_IN_EV = 27.211386245988
TOP = 3


def molecule_facts(candidate: CandidateRecord) -> dict[str, Any]:
    """A molecule's property on the QM9 scale and its distance to the target (empty for a
    candidate that is no molecule)."""
    extras, parameters = candidate.extras, candidate.parameters
    if "smiles" not in extras or "property" not in parameters or "target" not in extras:
        return {}
    value, target = float(parameters["property"]), float(extras["target"])
    hartree = _hartree(str(extras.get("property_name")), value)
    return {
        "candidate": candidate.id,
        "smiles": extras["smiles"],
        "property": extras.get("property_name", "property"),
        "normalized": value,
        "target": target,
        "distance": abs(value - target),
        "hartree": hartree,
        "ev": None if hartree is None else hartree * HARTREE_IN_EV,
        "loss": candidate.loss,
    }


def top_facts(candidates: Sequence[CandidateRecord]) -> list[dict[str, Any]]:
    """:func:`molecule_facts` of each candidate that is a molecule."""
    return [facts for facts in map(molecule_facts, candidates) if facts]


def _hartree(label: str, normalized: float) -> float | None:
    """The normalized value back in Hartree on the QM9 B3LYP scale (QM9 mean + value x std);
    None for a property the molecule tasks do not name."""
    key = {name: key for key, name in PROPERTY_LABELS.items()}.get(label)
    if key is None:
        return None
    stats = QM9_STATISTICS[key]
    return stats.mean + normalized * stats.std


def _loss(value: float | None) -> str:
    return f"{value:.4g}" if value is not None and math.isfinite(value) else "inf"


def molecules_table(molecules: list[dict[str, Any]]) -> Table:
    """Rank, SMILES, the normalized property and its value in Hartree and eV, the target, the
    distance to it and the loss of each top molecule."""
    rows = []
    for rank, m in enumerate(molecules, 1):
        scale = "-" if m["hartree"] is None else f"{m['hartree']:+.4f} Ha ({m['ev']:+.2f} eV)"
        rows.append([
            str(rank), m["candidate"], m["smiles"], f"{m['normalized']:+.3f}", scale,
            f"{m['target']:+g}", f"{m['distance']:.3g}", _loss(m["loss"]),
        ])  # fmt: skip
    name = molecules[0]["property"]
    header = ["rank", "candidate", "SMILES", f"{name}, normalized", f"{name}, QM9 scale",
              "target", "distance", "loss"]  # fmt: skip
    return Table(header, rows)


def summary_blocks(view: ReportView) -> list:
    """The table of the top molecules (none when no candidate is a molecule)."""
    molecules = top_facts(view.top)
    if not molecules:
        return []
    return [Text("Top molecules (distinct SMILES), property on the QM9 scale:"),
            molecules_table(molecules)]  # fmt: skip


def screen_lines(findings: dict[str, Any]) -> list[str]:
    """The best molecule (SMILES) and its property: in Hartree and eV on the QM9 scale, and
    normalized (in QM9 standard deviations from the QM9 mean) against the target; none when
    the run's facts name no molecule."""
    molecules = [m for m in findings.get("molecules") or [] if isinstance(m, dict)]
    best = (findings.get("best") or {}).get("candidate")
    # the best's own facts, else the first distinct molecule's (the best's, under another id)
    found = next((m for m in molecules if m.get("candidate") == best), None)
    m = found or (molecules[0] if molecules else None)
    if m is None or "smiles" not in m or "normalized" not in m:
        return []
    line = f"its {m.get('property', 'property')}: "
    if m.get("hartree") is not None and m.get("ev") is not None:
        line += f"{m['hartree']:+.4f} Ha ({m['ev']:+.2f} eV) on the QM9 B3LYP scale, "
    line += f"{m['normalized']:+.3f} normalized (target {m.get('target', 0.0):+g})"
    return [f"best molecule (SMILES): {m['smiles']}", line]


def pictures_section(view: ReportView) -> Section:
    """2D depictions of the top molecules; a SMILES RDKit cannot read only loses the picture."""
    title = f"Top {TOP} molecules"
    view.say("drawing the top molecules")
    try:
        png = plot_molecules(view.top, view.folder / "molecules.png")
    except Exception as error:  # a SMILES RDKit cannot read only loses this picture
        return Section(title, [Text(f"Skipped: the depiction failed ({error!r}).")])
    return Section(title, [Image(png.name, "top molecules")])


def smiles_of(candidate: CandidateRecord) -> str:
    """The candidate's SMILES: as evaluated if recorded, else read from its code."""
    if candidate.extras.get("smiles"):
        return str(candidate.extras["smiles"])
    from tasks.molecules.solution import parse_solution

    return parse_solution(candidate.code).smiles


def plot_molecules(candidates: Sequence[CandidateRecord], path: Path) -> Path:
    """2D depictions of ``candidates`` side by side, each with its id and loss."""
    from rdkit import Chem
    from rdkit.Chem import Draw, rdDepictor

    options = Draw.MolDrawOptions()
    options.legendFontSize = 22
    molecules = [Chem.MolFromSmiles(smiles_of(candidate)) for candidate in candidates]
    legends = [f"#{rank} {c.id}: loss {c.loss:.4g}" for rank, c in enumerate(candidates, 1)]
    preferred = rdDepictor.GetPreferCoordGen()
    rdDepictor.SetPreferCoordGen(True)  # bridged rings without overlapping atoms
    try:
        image = Draw.MolsToGridImage(
            molecules, molsPerRow=len(molecules), subImgSize=(450, 400), legends=legends,
            drawOptions=options,
        )  # fmt: skip
    finally:
        rdDepictor.SetPreferCoordGen(preferred)
    image.save(path, dpi=(DPI, DPI))
    return path
