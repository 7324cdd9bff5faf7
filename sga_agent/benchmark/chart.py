"""``ranks.png``: each method's rank per task and its mean rank (the paper's Figure 4).

Left, the rank per task: a radar chart as in the paper (one spoke per task, outer = better)
when there are three tasks or more, a dot plot for fewer (a radar of one or two spokes shows
nothing). Right, the mean rank over the tasks, best on top. Drawn with the report's style
(:mod:`sga_agent.report.plots`), at a fixed size.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib
from matplotlib.axes import Axes

from sga_agent.benchmark.table import Ranks, mean_ranks
from sga_agent.report.plots import DPI, new_figure

#: Width and height in inches (at :data:`sga_agent.report.plots.DPI`).
RANKS_SIZE = (12.0, 5.0)
MIN_RADAR_TASKS = 3
#: The radar's ring labels (ranks) stay legible over the polygons.
RING_LABEL_BOX = {"boxstyle": "round,pad=0.15", "facecolor": "white", "edgecolor": "none",
                  "alpha": 0.8}  # fmt: skip


def colours(count: int) -> list[tuple[float, ...]]:
    """Distinct colours for ``count`` methods."""
    palette = matplotlib.colormaps["tab10" if count <= 10 else "tab20"]
    return [palette(i % palette.N) for i in range(count)]


def plot_ranks(ranks: Ranks, path: Path) -> Path:
    """Draw ``ranks`` (task -> method -> rank, 1 = best) into ``path`` (PNG)."""
    tasks = list(ranks)
    labels = list(ranks[tasks[0]])
    palette = dict(zip(labels, colours(len(labels)), strict=True))
    figure = new_figure(*RANKS_SIZE)
    figure.set_layout_engine("constrained")  # makes room for the legend and long labels
    grid = figure.add_gridspec(1, 2)
    if len(tasks) >= MIN_RADAR_TASKS:
        _radar(figure.add_subplot(grid[0, 0], projection="polar"), ranks, palette)
    else:
        _dots(figure.add_subplot(grid[0, 0]), ranks, palette)
    _mean_bars(figure.add_subplot(grid[0, 1]), ranks, palette)
    figure.legend(loc="outside lower center", ncols=min(len(labels), 4), frameon=False,
                  fontsize=10)  # fmt: skip
    figure.suptitle(f"Ranks of {len(labels)} methods on {len(tasks)} tasks (by mean final loss)")
    figure.savefig(path, dpi=DPI)
    return path


def _radar(axes: Axes, ranks: Ranks, palette: dict[str, tuple[float, ...]]) -> None:
    tasks, count = list(ranks), len(palette)
    angles = [2 * math.pi * i / len(tasks) for i in range(len(tasks))]
    for label, colour in palette.items():
        radii = [count + 1 - ranks[task][label] for task in tasks]
        axes.plot([*angles, angles[0]], [*radii, radii[0]], "-o", color=colour, label=label,
                  linewidth=2, markersize=5)  # fmt: skip
        axes.fill([*angles, angles[0]], [*radii, radii[0]], color=colour, alpha=0.08)
    axes.set_theta_offset(math.pi / 2)
    axes.set_theta_direction(-1)
    axes.set_xticks(angles)
    axes.set_xticklabels(tasks)
    axes.tick_params(axis="x", pad=12)
    axes.set_ylim(0, count + 0.25)
    axes.set_yticks(range(1, count + 1))
    axes.set_yticklabels([f"{count + 1 - r}" for r in range(1, count + 1)], fontsize=9,
                         color="#444444", bbox=RING_LABEL_BOX)  # fmt: skip
    axes.set_rlabel_position(180 / len(tasks))  # between the first two spokes
    axes.set_title("Rank per task (outer = better)", pad=18)


def _dots(axes: Axes, ranks: Ranks, palette: dict[str, tuple[float, ...]]) -> None:
    tasks, count = list(ranks), len(palette)
    spacing = min(0.1, 0.5 / count)  # apart enough that tied methods stay visible
    for index, (label, colour) in enumerate(palette.items()):
        offset = (index - (count - 1) / 2) * spacing
        xs = [position + offset for position in range(len(tasks))]
        axes.plot(xs, [ranks[task][label] for task in tasks], "-o", color=colour, label=label,
                  linewidth=1.5, markersize=9)  # fmt: skip
    axes.set_xticks(range(len(tasks)))
    axes.set_xticklabels(tasks)
    axes.set_xlim(-0.6, len(tasks) - 0.4)
    axes.set_ylim(count + 0.5, 0.5)
    axes.set_yticks(range(1, count + 1))
    axes.set_ylabel("rank (1 = best)")
    axes.set_xlabel("task")
    axes.grid(True, axis="y", alpha=0.3)
    axes.set_title("Rank per task")


def _mean_bars(axes: Axes, ranks: Ranks, palette: dict[str, tuple[float, ...]]) -> None:
    means = mean_ranks(ranks)
    ordered = sorted(means, key=lambda label: means[label])
    positions = range(len(ordered))
    axes.barh(positions, [means[label] for label in ordered],
              color=[palette[label] for label in ordered], height=0.6)  # fmt: skip
    for position, label in zip(positions, ordered, strict=True):
        axes.text(means[label] + 0.05, position, f"{means[label]:.2f}", va="center")
    axes.set_yticks(positions)
    axes.set_yticklabels(ordered)
    axes.invert_yaxis()
    axes.set_xlim(0, len(ordered) + 0.6)
    axes.set_xlabel(f"mean rank over {len(ranks)} tasks (lower is better)")
    axes.grid(True, axis="x", alpha=0.3)
    axes.set_title("Mean rank")
