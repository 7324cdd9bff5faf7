"""The report's optional task-specific pictures.

The task packages (Taichi, torch, RDKit) are imported inside these functions, by task family,
never at module level: ``sga_agent`` itself depends on no concrete task. A run of a task from
another package gets no task-specific picture.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from sga_agent.registry import task_entry_points
from sga_agent.report.data import Candidate, Run
from sga_agent.report.plots import DPI, new_figure, save
from sga_agent.task import FreeRun

LOSS_LABELS = {
    "constitutive": "loss: mean squared position error (m²)",
    "molecules": "loss (dimensionless, normalised property)",
}
MOTION_FRAMES, GIF_FPS = 4, 10


def task_family(task: str) -> str:
    """``constitutive``, ``molecules`` or ``other``, from the task's entry point (no import)."""
    point = task_entry_points().get(task)
    module = point.value.split(":")[0] if point is not None else ""
    return next((name for name in LOSS_LABELS if module == f"tasks.{name}"), "other")


def loss_label(task: str) -> str:
    return LOSS_LABELS.get(task_family(task), "loss")


# ---------------------------------------------------------------------- constitutive motion


def _limits(positions: np.ndarray) -> tuple[tuple[float, float], tuple[float, float]]:
    low, high = positions[..., :2].min(axis=(0, 1)), positions[..., :2].max(axis=(0, 1))
    pad = 0.05 * (high - low).max()
    return (low[0] - pad, high[0] + pad), (low[1] - pad, high[1] + pad)


def _panel(axes, points: np.ndarray, limits, title: str, colour: str) -> None:
    axes.clear()
    finite = points[np.isfinite(points).all(axis=1)]
    axes.scatter(finite[:, 0], finite[:, 1], s=1, color=colour, linewidths=0)
    axes.set_xlim(*limits[0])
    axes.set_ylim(*limits[1])
    axes.set_aspect("equal")
    axes.set_title(title)
    axes.set_xlabel("x (m)")
    axes.set_ylabel("y (m)")


def plot_motion(run: Run, best: Candidate, free: FreeRun, folder: Path) -> tuple[Path, Path]:
    """The observation above, the best law's free run below, at a few steps (PNG); every kept
    frame of both as a GIF."""
    from matplotlib.animation import PillowWriter

    steps, truth, simulated = free.frames, free.observed, free.positions
    limits = _limits(truth)
    frames = np.linspace(0, len(steps) - 1, MOTION_FRAMES).round().astype(int)
    figure = new_figure(2.8 * MOTION_FRAMES, 6.0)
    grid = figure.subplots(2, MOTION_FRAMES)
    for column, frame in enumerate(frames):
        step = steps[frame]
        _panel(grid[0, column], truth[frame], limits, f"observed, step {step}", "#264653")
        _panel(grid[1, column], simulated[frame], limits, f"{best.id}, step {step}", "#e76f51")
    figure.suptitle(f"{run.task}: observed motion vs the best law's free run (x-y projection)")
    png = save(figure, folder / "motion.png")

    animation: Figure = new_figure(8.0, 4.2)
    left, right = animation.subplots(1, 2)
    writer = PillowWriter(fps=GIF_FPS)
    gif = folder / "motion.gif"
    with writer.saving(animation, str(gif), dpi=100):
        for frame, step in enumerate(steps):
            _panel(left, truth[frame], limits, f"observed, step {step}", "#264653")
            _panel(right, simulated[frame], limits, f"{best.id}, step {step}", "#e76f51")
            animation.tight_layout()
            writer.grab_frame()
    return png, gif


# ---------------------------------------------------------------------- molecules


def smiles_of(candidate: Candidate) -> str:
    """The candidate's SMILES: as evaluated if recorded, else read from its code."""
    if candidate.extras.get("smiles"):
        return str(candidate.extras["smiles"])
    from tasks.molecules.solution import parse_solution

    return parse_solution(candidate.code).smiles


def plot_molecules(candidates: list[Candidate], path: Path) -> Path:
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
