"""The search figures: the bilevel zigzag, the best loss against evaluations and wall time and
per iteration, outcomes per iteration, inner-loop curves.

Figures are drawn on :class:`matplotlib.figure.Figure` objects (the Agg canvas, no pyplot state,
no display) at a fixed size so that a paper can place them as they are.
"""

from __future__ import annotations

import math
from pathlib import Path

from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.patches import Patch
from matplotlib.ticker import MaxNLocator, NullFormatter

from sga_agent.report.data import Candidate, Run
from sga_agent.task import DPI, FONT, STATUSES

#: One colour per outcome, failures in warm colours.
STATUS_COLOURS = dict(zip(STATUSES, (
    "#2a9d8f", "#e9c46a", "#f4a261", "#e76f51", "#8d6e63", "#9c27b0", "#455a64",
), strict=True))  # fmt: skip
CURVES_WIDTH, CURVES_ROW_HEIGHT, MAX_PARAMETER_PANELS = 11.0, 2.6, 3
#: A loss curve gets a log axis when it spans more than this factor (two decades).
LOG_SPAN = 100.0


def new_figure(width: float, height: float) -> Figure:
    import matplotlib

    matplotlib.rcParams.update(FONT)
    return Figure(figsize=(width, height), dpi=DPI)


def save(figure: Figure, path: Path) -> Path:
    figure.tight_layout()
    figure.savefig(path, dpi=DPI)
    return path


def _iterations(run: Run) -> list[int]:
    """The iterations with a full fit or a screen, in order."""
    return sorted({candidate.iteration for candidate in run.every_candidate()})


def outcome_counts(run: Run, screens: bool = False) -> dict[int, dict[str, int]]:
    """For each iteration (with a full fit or a screen), how many candidates' full fits, or
    with ``screens`` their screens, ended in each status."""
    counts = {iteration: dict.fromkeys(STATUSES, 0) for iteration in _iterations(run)}
    for candidate in run.screens() if screens else run.candidates:
        outcome = candidate.screen if screens else candidate
        if outcome is not None:
            counts[candidate.iteration][outcome.status] += 1
    return counts


def promoted_counts(run: Run) -> dict[int, int]:
    """For each iteration (with a full fit or a screen), how many screens were promoted to a
    full fit."""
    counts = dict.fromkeys(_iterations(run), 0)
    for candidate in run.screens():
        counts[candidate.iteration] += candidate.promoted
    return counts


def best_per_iteration(run: Run) -> tuple[dict[int, float], dict[int, float]]:
    """The best finite loss found in each iteration, and the best found so far."""
    within: dict[int, float] = {}
    for candidate in run.ranked():
        within.setdefault(candidate.iteration, candidate.loss)
    so_far, best = {}, math.inf
    for iteration in run.iterations:
        best = min(best, within.get(iteration, math.inf))
        if math.isfinite(best):
            so_far[iteration] = best
    return dict(sorted(within.items())), so_far


def plot_best_loss(run: Run, path: Path, loss_label: str) -> Path:
    """Line plot of the best loss so far per iteration (log scale); the seed is iteration 0."""
    within, so_far = best_per_iteration(run)
    figure = new_figure(7.0, 4.0)
    axes = figure.add_subplot()
    axes.plot(list(so_far), list(so_far.values()), "-o", color="#264653", label="best so far")
    axes.plot(list(within), list(within.values()), "x", color="#e76f51", markersize=9,
              label="best of the iteration")  # fmt: skip
    if all(value > 0 for value in within.values()):
        axes.set_yscale("log")
    axes.set_xticks(run.iterations)
    axes.set_xlabel("iteration (0 = seed)")
    axes.set_ylabel(loss_label)
    axes.set_title(f"{run.task}: best loss per iteration")
    axes.grid(True, which="both", alpha=0.3)
    axes.legend()
    return save(figure, path)


def _stack(
    axes: Axes, xs: list[float], counts: list[dict[str, int]], width: float, hatch: str = ""
) -> None:
    """Stacked bars at ``xs``, one per ``counts`` (by status), in the statuses' colours."""
    bottom = [0] * len(xs)
    for status in STATUSES:
        heights = [count[status] for count in counts]
        if any(heights):
            axes.bar(xs, heights, bottom=bottom, color=STATUS_COLOURS[status], width=width,
                     hatch=hatch, edgecolor="white" if hatch else None)  # fmt: skip
            bottom = [b + h for b, h in zip(bottom, heights, strict=True)]


def outcomes_figure(run: Run) -> Figure:
    """Stacked bars: the candidates of each iteration by outcome; in a multi-fidelity search,
    two per iteration: its screens (hatched, left) and its full fits (right)."""
    counts = outcome_counts(run)
    iterations = list(counts)
    figure = new_figure(7.0, 4.0)
    axes = figure.add_subplot()
    shown = [counts[i] for i in iterations]
    kinds: list[Patch] = []  # what tells the two bars of an iteration apart
    if run.screens():
        by_iteration = outcome_counts(run, screens=True)
        screens = [by_iteration[i] for i in iterations]
        _stack(axes, [i - 0.2 for i in iterations], screens, 0.38, hatch="///")
        _stack(axes, [i + 0.2 for i in iterations], shown, 0.38)
        shown += screens
        kinds = [Patch(facecolor="white", edgecolor="#555555", hatch="///", label="screens"),
                 Patch(facecolor="white", edgecolor="#555555", label="full fits")]  # fmt: skip
        title = "screens (hatched) and full fits per iteration"
    else:
        _stack(axes, iterations, shown, 0.7)
        title = "evaluation outcomes per iteration"
    axes.set_xticks(iterations)
    axes.set_xlabel("iteration (0 = seed)")
    axes.set_ylabel("candidates (count)")
    axes.yaxis.get_major_locator().set_params(integer=True)
    axes.set_title(f"{run.task}: {title}")
    outcomes = [Patch(color=STATUS_COLOURS[status], label=status) for status in STATUSES
                if any(count[status] for count in shown)]  # fmt: skip
    axes.legend(handles=[*outcomes, *kinds], title="outcome", loc="upper left",
                bbox_to_anchor=(1.01, 1.0))  # fmt: skip
    return figure


def plot_outcomes(run: Run, path: Path) -> Path:
    """Draw :func:`outcomes_figure` into ``path``."""
    return save(outcomes_figure(run), path)


def evaluated_in_order(run: Run) -> list[Candidate]:
    """The candidates in the order their evaluations were recorded (by id where no time)."""
    return sorted(run.candidates, key=lambda c: (c.time is None, c.time or 0.0, c.id))


def plot_zigzag(run: Run, path: Path, loss_label: str) -> Path:
    """The bilevel picture (the paper's Figure 3): each candidate's loss at its proposed
    constants (the inner loop's first epoch) and after fitting, joined in evaluation order."""
    figure = new_figure(9.0, 4.2)
    axes = figure.add_subplot()
    xs, ys, proposed, fitted, failed = [], [], [], [], []
    boundaries, last_iteration = [], None
    for index, candidate in enumerate(evaluated_in_order(run)):
        losses = candidate.curves.get("loss") or []
        if candidate.iteration != last_iteration and index:
            boundaries.append(index - 0.25)
        last_iteration = candidate.iteration
        if candidate.status != "ok" or not losses or not math.isfinite(candidate.loss):
            failed.append(index)
            continue
        start = losses[0] if math.isfinite(losses[0]) else candidate.loss
        xs += [index, index + 0.5]
        ys += [start, candidate.loss]
        proposed.append((index, start))
        fitted.append((index + 0.5, candidate.loss))
    axes.plot(xs, ys, "-", color="#8d99ae", linewidth=1, zorder=1)
    if proposed:
        axes.scatter(*zip(*proposed, strict=True), s=30, facecolors="white",
                     edgecolors="#e76f51", label="proposed constants", zorder=2)  # fmt: skip
        axes.scatter(*zip(*fitted, strict=True), s=30, color="#264653",
                     label="after the inner optimisation", zorder=3)  # fmt: skip
        if all(y > 0 for y in ys):
            axes.set_yscale("log")
        axes.legend()
    else:
        axes.text(0.5, 0.5, "no scored candidate", ha="center", transform=axes.transAxes)
    if failed:  # along the bottom edge: no loss to draw, but the gap is explained
        axes.scatter(failed, [0.02] * len(failed), marker="x", color="#9c27b0",
                     transform=axes.get_xaxis_transform(), label="not scored")  # fmt: skip
        axes.legend()
    for x in boundaries:
        axes.axvline(x, color="#bbbbbb", linestyle=":", linewidth=1)
    axes.xaxis.get_major_locator().set_params(integer=True)
    axes.set_xlabel("evaluation, in order (0 = seed; dotted lines between iterations)")
    axes.set_ylabel(loss_label)
    axes.set_title(f"{run.task}: loss before and after fitting each candidate")
    axes.grid(True, which="major", alpha=0.3)
    return save(figure, path)


def best_so_far(run: Run) -> list[tuple[Candidate, float]]:
    """Each candidate in evaluation order with the best finite loss found up to it."""
    best, found = math.inf, []
    for candidate in evaluated_in_order(run):
        if candidate.status == "ok" and math.isfinite(candidate.loss):
            best = min(best, candidate.loss)
        found.append((candidate, best))
    return found


def plot_progress(run: Run, path: Path, loss_label: str) -> Path:
    """The best loss so far against evaluations (left) and against wall time (right)."""
    figure = new_figure(11.0, 4.0)
    by_count, by_time = figure.subplots(1, 2)
    steps = [(i + 1, best) for i, (_, best) in enumerate(best_so_far(run)) if math.isfinite(best)]
    if steps:
        by_count.step(*zip(*steps, strict=True), where="post", color="#264653", marker="o",
                      markersize=3)  # fmt: skip
    timed = [
        ((c.time - run.started) / 60, best) for c, best in best_so_far(run)
        if c.time is not None and run.started is not None and math.isfinite(best)
    ]  # fmt: skip
    if timed:
        by_time.step(*zip(*timed, strict=True), where="post", color="#2a9d8f", marker="o",
                     markersize=3)  # fmt: skip
    else:
        by_time.text(0.5, 0.5, "no times recorded", ha="center", transform=by_time.transAxes)
    for axes, label in ((by_count, "evaluations"), (by_time, "wall time since the start (min)")):
        if steps and all(best > 0 for _, best in steps):
            axes.set_yscale("log")
        axes.set_xlabel(label)
        axes.set_ylabel(loss_label if axes is by_count else "")
        axes.grid(True, which="both", alpha=0.3)
    by_count.xaxis.get_major_locator().set_params(integer=True)
    figure.suptitle(f"{run.task}: best loss so far")
    return save(figure, path)


def curves_size(candidates: list[Candidate]) -> tuple[float, float]:
    """The inner-loop figure's size in inches for these candidates."""
    return CURVES_WIDTH, CURVES_ROW_HEIGHT * max(1, len(candidates))


#: A series of at most this many points has each value written above its marker.
LABELLED_POINTS = 2


def draw_series(axes: Axes, values: list[float], colour: str) -> None:
    """``values`` against their index (epochs), on integer epochs. A fit that stopped after one
    or two evaluations gets each value written above its marker and an epoch axis of two
    epochs (matplotlib's default around a lone point runs from -0.05 to 0.05); one whose values
    are all equal gets its value written once and y-limits 10% either side of it."""
    axes.plot(range(len(values)), values, "-o", markersize=3, color=colour)
    axes.xaxis.set_major_locator(MaxNLocator(integer=True))
    finite = [value for value in values if math.isfinite(value)]
    if not finite:
        return
    low, high = min(finite), max(finite)
    if len(values) <= LABELLED_POINTS:
        axes.set_xlim(-0.5, LABELLED_POINTS - 0.5)  # room for the labels right of the markers
        labelled = list(range(len(values)))
    else:
        labelled = [0] if low == high else []
    if low == high:  # one value, however many points: a span around it
        pad = 0.1 * abs(low) or 1.0
        axes.set_ylim(low - pad, high + pad)
    elif labelled:
        axes.margins(y=0.25)  # room for the top marker's label below the frame
    for index in labelled:
        if math.isfinite(values[index]):
            axes.annotate(f"{values[index]:.4g}", (index, values[index]), xytext=(-4, 6),
                          textcoords="offset points", fontsize=9, color=colour)  # fmt: skip


def curves_figure(candidates: list[Candidate], loss_label: str) -> Figure:
    """One row per candidate: its loss over epochs, then its first parameters over epochs."""
    figure = new_figure(*curves_size(candidates))
    columns = 1 + MAX_PARAMETER_PANELS
    grid = figure.add_gridspec(max(1, len(candidates)), columns)
    for row, candidate in enumerate(candidates):
        losses = candidate.curves.get("loss", [])
        axes = figure.add_subplot(grid[row, 0])
        draw_series(axes, losses, "#264653")
        if losses and min(losses) > 0 and max(losses) > LOG_SPAN * min(losses):
            axes.set_yscale("log")
            axes.yaxis.set_minor_formatter(NullFormatter())
        else:  # over a short span a log axis labels its minor ticks; a linear one reads better
            axes.ticklabel_format(axis="y", style="sci", scilimits=(-3, 4), useMathText=True)
        axes.set_title(f"#{row + 1} {candidate.id}: loss", loc="left")
        axes.set_ylabel("loss")
        axes.set_xlabel("epoch")
        names = [name for name in candidate.curves if name != "loss"]
        for column, name in enumerate(names[:MAX_PARAMETER_PANELS], start=1):
            axes = figure.add_subplot(grid[row, column])
            draw_series(axes, candidate.curves[name], "#2a9d8f")
            axes.ticklabel_format(axis="y", useOffset=False)  # an offset text hits the title
            axes.set_title(name, loc="left")
            axes.set_xlabel("epoch")
            axes.set_ylabel("value")
        if not names:
            axes = figure.add_subplot(grid[row, 1:])
            axes.axis("off")
            axes.text(0.02, 0.5, "no trainable parameters", va="center")
    if not candidates:
        figure.add_subplot().text(0.5, 0.5, "no scored candidate", ha="center")
    hidden = any(len(c.curves) - 1 > MAX_PARAMETER_PANELS for c in candidates)
    note = f"; first {MAX_PARAMETER_PANELS} parameters shown, all in curves.json" if hidden else ""
    figure.suptitle(f"Inner-loop optimisation of the top distinct solutions\n{loss_label}{note}")
    return figure


def plot_curves(candidates: list[Candidate], path: Path, loss_label: str) -> Path:
    """Draw :func:`curves_figure` into ``path``."""
    return save(curves_figure(candidates, loss_label), path)
