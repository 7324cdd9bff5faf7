"""Static pictures of particle trajectories, drawn with matplotlib's Agg backend.

Nothing here touches pyplot's global state or needs a display: every figure is a
:class:`matplotlib.figure.Figure` attached to its own
:class:`~matplotlib.backends.backend_agg.FigureCanvasAgg`, so rendering works on a
headless machine and from several threads.

The simulator's y axis points up; the pictures keep it vertical. Simulator coordinates
``(x, y, z)`` are drawn on the plot axes ``(x, z, y)`` with the plot's depth axis
reversed, which is a rotation (not a mirror image) of the simulated scene.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

#: Accepted values of ``color_by``.
COLOR_MODES = ("height", "initial_height", "none")
#: Width and height of one panel, in inches.
PANEL_SIZE = 3.0
#: Width of the strip on the right that holds the colour bar, in inches.
COLORBAR_STRIP = 0.6
#: Default resolution, in dots per inch.
DEFAULT_DPI = 150

_CMAP = "viridis"
_SOLID_COLOR = "#3b6ea8"
_VIEW = {"elev": 18.0, "azim": -52.0}
_ZOOM = 1.08
_BOX_COLOR = "#4d4d4d"
_FLOOR_COLOR = "#d9d4c7"


def figure_size(
    num_panels: int, dpi: float = DEFAULT_DPI, colorbar: bool = True
) -> tuple[int, int]:
    """Pixel size ``(width, height)`` of the PNG that :func:`render_frames` writes.

    Parameters
    ----------
    num_panels : int
        Number of frames drawn side by side.
    dpi : float
        Resolution passed to :func:`render_frames`.
    colorbar : bool
        Whether the picture has a colour bar strip on the right.

    Returns
    -------
    tuple of int
        Width and height in pixels.
    """
    width, height = _figure_inches(num_panels, colorbar)
    return round(width * dpi), round(height * dpi)


def _figure_inches(num_panels: int, colorbar: bool) -> tuple[float, float]:
    """Figure size in inches: one square panel per frame plus the colour bar strip."""
    return num_panels * PANEL_SIZE + (COLORBAR_STRIP if colorbar else 0.0), PANEL_SIZE


def render_frames(
    positions: np.ndarray,
    path: str | os.PathLike[str],
    titles: Sequence[str] | None = None,
    domain_size: float = 1.0,
    color_by: str = "height",
    dpi: float = DEFAULT_DPI,
    *,
    floor: float | None = 0.0,
    point_size: float | None = None,
) -> Path:
    """Draw a row of 3D scatter plots, one per frame, and save them as a PNG.

    Parameters
    ----------
    positions : (frames, N, 3) array
        Particle positions in simulator coordinates (y up), e.g. the output of
        :meth:`taichi_mpm.Simulator.forward`.
    path : str or path-like
        Output file; its suffix must be ``.png``. Missing parent folders are created.
    titles : sequence of str, optional
        One title per frame (for example the simulated time). Default: ``"frame i"``.
    domain_size : float
        Side of the cubic domain ``[0, domain_size]^3`` drawn as a wire box.
    color_by : {"height", "initial_height", "none"}
        ``"height"`` colours each particle by its current height (one colour scale shared
        by all panels); ``"initial_height"`` by its height in the first frame, so colours
        follow the material and show how it deforms; ``"none"`` draws one solid colour.
    dpi : float
        Resolution in dots per inch; see :func:`figure_size` for the pixel size.
    floor : float or None, keyword-only
        Height of the floor plane that is shaded (for example the top of the bottom wall),
        with the particles' shadows on it. ``None`` draws no floor.
    point_size : float, optional, keyword-only
        Marker area in points^2. Default: scaled to the number of particles.

    Returns
    -------
    pathlib.Path
        The file written.

    Raises
    ------
    ValueError
        If ``positions`` has the wrong shape or non-finite values, if ``titles`` does not
        match the number of frames, or if an argument is out of range.
    """
    x = np.asarray(positions, dtype=np.float64)
    if x.ndim != 3 or x.shape[2] != 3 or x.shape[0] == 0 or x.shape[1] == 0:
        raise ValueError(
            f"positions must have shape (frames, N, 3) with frames, N >= 1; got {x.shape}"
        )
    if not np.isfinite(x).all():
        raise ValueError("positions contain NaN or inf; the simulation has diverged")
    num_frames = x.shape[0]
    if titles is None:
        titles = [f"frame {i}" for i in range(num_frames)]
    titles = list(titles)
    if len(titles) != num_frames:
        raise ValueError(f"got {len(titles)} titles for {num_frames} frames")
    if color_by not in COLOR_MODES:
        raise ValueError(f"color_by={color_by!r} is unknown; use one of {COLOR_MODES}")
    if not (np.isfinite(domain_size) and domain_size > 0):
        raise ValueError(f"domain_size={domain_size} must be a positive number")
    if not (np.isfinite(dpi) and dpi > 0):
        raise ValueError(f"dpi={dpi} must be a positive number")
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise ValueError(f"{path} must end in .png")

    heights = x[..., 1]
    colorbar = color_by != "none"
    if colorbar:
        low, high = float(heights.min()), float(heights.max())
        if high - low < 1e-9 * domain_size:
            low, high = low - 0.5 * domain_size, high + 0.5 * domain_size
        norm = Normalize(low, high)
        cmap = colormaps[_CMAP]
    if point_size is None:
        # About 6 pt^2 for 1000 particles, smaller for denser clouds, within [0.5, 12].
        point_size = float(np.clip(6.0 * (1000.0 / x.shape[1]) ** (2.0 / 3.0), 0.5, 12.0))

    width, height = _figure_inches(num_frames, colorbar)
    fig = Figure(figsize=(width, height), dpi=dpi, facecolor="white")
    FigureCanvasAgg(fig)
    panel_fraction = PANEL_SIZE / width
    for i in range(num_frames):
        ax = fig.add_axes(
            (i * panel_fraction, 0.0, panel_fraction, 0.9), projection="3d", facecolor="none"
        )
        if color_by == "height":
            colors = cmap(norm(heights[i]))
        elif color_by == "initial_height":
            colors = cmap(norm(heights[0]))
        else:
            colors = _SOLID_COLOR
        _draw_panel(ax, x[i], colors, domain_size, floor, point_size)
        fig.text(
            (i + 0.5) * panel_fraction,
            0.94,
            titles[i],
            ha="center",
            va="center",
            fontsize=10,
            color="#222222",
        )
    if colorbar:
        strip = COLORBAR_STRIP / width
        cax = fig.add_axes((1.0 - 0.85 * strip, 0.2, 0.16 * strip, 0.6))
        bar = fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), cax=cax)
        label = "height y" if color_by == "height" else "initial height y"
        bar.set_label(label, fontsize=8)
        bar.ax.tick_params(labelsize=7, length=2)
        bar.outline.set_linewidth(0.5)

    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi, format="png", facecolor="white")
    return path


def _draw_panel(ax, points: np.ndarray, colors, size: float, floor, point_size: float) -> None:
    """One 3D scatter panel in plot coordinates (x, z, y) with a reversed z axis."""
    ax.set_proj_type("persp", focal_length=2.0)
    ax.computed_zorder = False  # draw in call order: floor, shadows, box, particles
    ax.view_init(**_VIEW)
    ax.set_xlim(0.0, size)
    ax.set_ylim(size, 0.0)  # reversed depth axis: keeps the scene right-handed
    ax.set_zlim(0.0, size)
    ax.set_box_aspect((1.0, 1.0, 1.0), zoom=_ZOOM)
    ax.set_axis_off()

    if floor is not None:
        f = float(np.clip(floor, 0.0, size))
        square = [[(0, 0, f), (size, 0, f), (size, size, f), (0, size, f)]]
        ax.add_collection3d(
            Poly3DCollection(square, facecolors=_FLOOR_COLOR, edgecolors="none", alpha=0.55)
        )
        inside = (points[:, 0] >= 0) & (points[:, 0] <= size)
        inside &= (points[:, 2] >= 0) & (points[:, 2] <= size)
        shadow = points[inside]
        ax.scatter(
            shadow[:, 0],
            shadow[:, 2],
            np.full(len(shadow), f),
            s=point_size * 0.8,
            c="#8a8577",
            alpha=0.12,
            linewidths=0,
            depthshade=False,
        )

    for start, end in _box_edges(size):
        ax.plot(*zip(start, end, strict=True), color=_BOX_COLOR, lw=0.6, alpha=0.7)
    ax.scatter(
        points[:, 0],
        points[:, 2],
        points[:, 1],
        s=point_size,
        c=colors,
        linewidths=0,
        depthshade=True,
    )
    # Small axis names at the far end of each edge leaving the origin (simulator names).
    pad = 0.06 * size
    label = {"fontsize": 7, "color": "#555555", "ha": "center", "va": "center"}
    ax.text(size + pad, 0.0, 0.0, "x", **label)
    ax.text(0.0, size + pad, 0.0, "z", **label)
    ax.text(0.0, 0.0, size + pad, "y", **label)


def _box_edges(size: float) -> list[tuple[tuple[float, ...], tuple[float, ...]]]:
    """The 12 edges of the cube [0, size]^3 as pairs of corners."""
    corners = [(i * size, j * size, k * size) for i in (0, 1) for j in (0, 1) for k in (0, 1)]
    edges = []
    for a, p in enumerate(corners):
        for q in corners[a + 1 :]:
            if sum(u != v for u, v in zip(p, q, strict=True)) == 1:
                edges.append((p, q))
    return edges
