"""A picture of a fit: observed and fitted particles at a few frames, and the loss curve.

Drawn with matplotlib's Agg backend on a :class:`~matplotlib.figure.Figure` of its own
(no pyplot state, no display). Simulator coordinates ``(x, y, z)`` are drawn on the plot
axes ``(x, z, y)`` so that y, the simulator's up, stays vertical, as in
:mod:`taichi_mpm.render`.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from taichi_mpm.frames import evenly_spaced

#: Most frames drawn.
MAX_PANELS = 4
PANEL_SIZE = 3.2  # inches
DPI = 120
_OBSERVED = "#222222"
_FITTED = "#e4572e"


def comparison_frames(num_frames: int, panels: int = MAX_PANELS) -> np.ndarray:
    """Indices of up to ``panels`` frames evenly spread over ``num_frames``, last included."""
    if num_frames < 1:
        raise ValueError("there are no frames to draw")
    return evenly_spaced(0, num_frames - 1, panels)


def plot_comparison(
    observed: np.ndarray,
    fitted: np.ndarray,
    times: Sequence[float],
    loss_curves: Sequence[Sequence[float]],
    path: str | os.PathLike[str],
    best_run: int = 0,
    title: str | None = None,
    panels: int = MAX_PANELS,
) -> Path:
    """Overlay observed and fitted particles at up to ``panels`` frames; add the loss curves.

    Parameters
    ----------
    observed, fitted : (frames, P, 3) arrays
        Observed positions and the fitted simulation at the same frames and particles.
    times : sequence of float
        Time of each frame (s).
    loss_curves : sequence of sequences of float
        Loss per iteration of each run; ``best_run`` is drawn bold.
    path : path-like
        PNG file to write; missing parent folders are created.
    title : str, optional
        Figure title.

    Returns
    -------
    pathlib.Path
        The file written.
    """
    observed = np.asarray(observed, dtype=np.float64)
    fitted = np.asarray(fitted, dtype=np.float64)
    if observed.ndim != 3 or observed.shape[2] != 3 or observed.shape != fitted.shape:
        raise ValueError(
            f"observed {observed.shape} and fitted {fitted.shape} must both be (frames, P, 3)"
        )
    if len(times) != observed.shape[0]:
        raise ValueError(f"got {len(times)} times for {observed.shape[0]} frames")
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise ValueError(f"{path} must end in .png")

    chosen = comparison_frames(observed.shape[0], panels)
    shown = np.concatenate([observed[chosen], fitted[chosen]])
    finite = shown[np.isfinite(shown).all(axis=-1)]
    center = 0.5 * (finite.min(axis=0) + finite.max(axis=0))
    half = 0.55 * float((finite.max(axis=0) - finite.min(axis=0)).max()) + 1e-9
    body = float(np.ptp(observed[0], axis=0).max()) or 1.0

    count = len(chosen) + 1
    width = count * PANEL_SIZE + 0.4
    fig = Figure(figsize=(width, PANEL_SIZE + 0.6), dpi=DPI, facecolor="white")
    FigureCanvasAgg(fig)
    size = max(1.0, min(14.0, 8.0 * (1000.0 / observed.shape[1]) ** (2.0 / 3.0)))
    panel = PANEL_SIZE / width
    for k, frame in enumerate(chosen):
        ax = fig.add_axes((k * panel, 0.08, panel, 0.74), projection="3d")
        ax.view_init(elev=18.0, azim=-52.0)
        ax.scatter(
            observed[frame, :, 0],
            observed[frame, :, 2],
            observed[frame, :, 1],
            s=2.2 * size,
            facecolors="none",
            edgecolors=_OBSERVED,
            linewidths=0.6,
            depthshade=False,
        )
        ax.scatter(
            fitted[frame, :, 0],
            fitted[frame, :, 2],
            fitted[frame, :, 1],
            s=0.6 * size,
            c=_FITTED,
            linewidths=0,
            depthshade=False,
        )
        ax.set_xlim(center[0] - half, center[0] + half)
        ax.set_ylim(center[2] + half, center[2] - half)  # reversed depth: a rotation
        ax.set_zlim(center[1] - half, center[1] + half)
        ax.set_box_aspect((1.0, 1.0, 1.0), zoom=0.9)
        for axis, label in ((ax.xaxis, "x"), (ax.yaxis, "z"), (ax.zaxis, "y")):
            axis.set_ticklabels([])
            axis.set_label_text(label, fontsize=8)
            axis.labelpad = -12
        rms = float(np.sqrt(((observed[frame] - fitted[frame]) ** 2).sum(axis=-1).mean()))
        ax.set_title(
            f"t = {times[frame]:.3g} s\nRMS gap {100 * rms / body:.2g}% of body size",
            fontsize=9,
        )
    legend = [
        Line2D([], [], ls="", marker="o", mfc="none", mec=_OBSERVED, label="observed"),
        Line2D([], [], ls="", marker="o", ms=4, color=_FITTED, label="fitted"),
    ]
    fig.legend(handles=legend, loc="lower left", fontsize=8, frameon=False, ncol=2)

    ax = fig.add_axes(((count - 0.83) * panel, 0.16, 0.78 * panel, 0.62))
    for run, curve in enumerate(loss_curves):
        curve = np.asarray(curve, dtype=np.float64)
        if len(curve) == 0:
            continue
        iterations = np.arange(1, len(curve) + 1)
        best = run == best_run
        ax.plot(
            iterations,
            np.maximum(curve, 1e-300),
            color=_FITTED if best else "#8c8c8c",
            lw=1.6 if best else 0.8,
            marker="." if len(curve) < 40 else None,
            label="best run" if best else None,
        )
    if any(len(curve) and np.all(np.asarray(curve) > 0) for curve in loss_curves):
        ax.set_yscale("log")
    ax.set_xlabel("iteration", fontsize=8)
    ax.set_title("loss", fontsize=9)
    ax.tick_params(which="both", labelsize=7)
    ax.grid(alpha=0.3)
    if len(loss_curves) > 1:
        ax.legend(fontsize=7, frameon=False)
    if title:
        fig.suptitle(title, fontsize=10)

    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI, format="png", facecolor="white")
    return path
