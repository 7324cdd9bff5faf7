"""What the constitutive tasks add to a run's report: the free run's error in the summary, and
the observed motion beside the best law's free run (a PNG of a few steps, a GIF of all kept).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from sga_agent.task import DPI, FONT, Assessment, Image, ReportView, Section, Text
from tasks.constitutive.free_run import FreeRun

LOSS_LABEL = "loss: mean squared position error (m²)"
MOTION_FRAMES, GIF_FPS = 4, 10


def free_run_line(assessment: Assessment | None, simulate: bool) -> list[str]:
    """The free-run errors in body sizes on the training and the held-out scene, as the
    summary's lines (none without a free run)."""
    runs = [run for run in (assessment.free_run, assessment.held_out) if run] if assessment else []
    if not runs:
        if assessment is not None and assessment.truth and not simulate:
            return ["- free run: skipped (`--no-motion`)"]
        return []
    lines = []
    for run in runs:
        where = f"on the **{run.scene}**"
        if run.unstable:
            lines.append(f"- free run of the best law {where}: unstable ({run.unstable})")
            continue
        lines.append(
            f"- free run of the best law {where} (from the initial state, no teacher forcing, "
            f"{run.steps} steps): RMS position error **{100 * run.final_error:.3g}%** of the "
            f"body size at the end, {100 * run.mean_error:.3g}% on average (body size "
            f"{run.body_size:.3g} m)"
        )
    return lines


def free_run_screen_lines(findings: dict[str, Any]) -> list[str]:
    """The best law's free-run errors on the training and the held-out scene, for the end of
    a search's screen (from summary.json)."""
    lines = []
    for free in (findings.get("free_run"), findings.get("held_out")):
        if not free:
            continue
        where = f"on the {free.get('scene', 'training scene')}"
        if free.get("unstable"):
            lines.append(f"free run of the best {where}: unstable ({free['unstable']})")
            continue
        lines.append(
            f"free run of the best {where} (no teacher forcing, {free['steps']} steps): RMS "
            f"position error {100 * float(free['final_error']):.3g}% of the body size at the "
            f"end, {100 * float(free['mean_error']):.3g}% on average"
        )
    return lines


def motion_section(view: ReportView) -> Section:
    """The observation against the best law's free run; "skipped" when there is none."""
    title, best = "Free run: the observation vs the best law", view.best
    if not view.simulate:
        return Section(title, [Text("Skipped (`--no-motion`).")])
    free = view.assessment.free_run if view.assessment else None
    if best is None or free is None or free.positions is None:
        why = "no candidate was scored" if best is None else "no free run of the best law"
        return Section(title, [Text(f"Skipped: {why}.")])
    view.say("drawing the free run")
    png, gif = plot_motion(view.task, best.id, free, view.folder)
    blocks = [
        Text(f"Particle positions (x-y projection) of the observation and of {best.id} with "
             "its fitted parameters, simulated from the initial state without teacher "
             "forcing (the fit restarts every segment from the observed state; this does "
             "not)."),
        Image(png.name, "observation vs the best law, free run"),
        Image(gif.name, "animation"),
    ]  # fmt: skip
    held_out = view.assessment.held_out
    if held_out is not None and held_out.positions is not None:
        view.say("drawing the free run on the held-out scene")
        png, gif = plot_motion(view.task, best.id, held_out, view.folder, "motion-held-out")
        blocks += [
            Text(f"The same on the held-out scene, which {best.id} was never fitted to."),
            Image(png.name, "held-out scene vs the best law, free run"),
            Image(gif.name, "animation, held-out scene"),
        ]
    return Section(title, blocks)


def _figure(width: float, height: float):
    import matplotlib
    from matplotlib.figure import Figure

    matplotlib.rcParams.update(FONT)
    return Figure(figsize=(width, height), dpi=DPI)


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


def plot_motion(
    task: str, best: str, free: FreeRun, folder: Path, stem: str = "motion"
) -> tuple[Path, Path]:
    """The observation above, the best law's (``best``, its id) free run below, at a few steps
    (``stem``.png); every kept frame of both as a GIF (``stem``.gif)."""
    from matplotlib.animation import PillowWriter

    steps, truth, simulated = free.frames, free.observed, free.positions
    limits = _limits(truth)
    frames = np.linspace(0, len(steps) - 1, MOTION_FRAMES).round().astype(int)
    figure = _figure(2.8 * MOTION_FRAMES, 6.0)
    grid = figure.subplots(2, MOTION_FRAMES)
    for column, frame in enumerate(frames):
        step = steps[frame]
        _panel(grid[0, column], truth[frame], limits, f"observed, step {step}", "#264653")
        _panel(grid[1, column], simulated[frame], limits, f"{best}, step {step}", "#e76f51")
    figure.suptitle(f"{task}, {free.scene}: observed motion vs the best law's free run "
                    "(x-y projection)")  # fmt: skip
    png = folder / f"{stem}.png"
    figure.tight_layout()
    figure.savefig(png, dpi=DPI)

    animation = _figure(8.0, 4.2)
    left, right = animation.subplots(1, 2)
    writer = PillowWriter(fps=GIF_FPS)
    gif = folder / f"{stem}.gif"
    with writer.saving(animation, str(gif), dpi=100):
        for frame, step in enumerate(steps):
            _panel(left, truth[frame], limits, f"observed, step {step}", "#264653")
            _panel(right, simulated[frame], limits, f"{best}, step {step}", "#e76f51")
            animation.tight_layout()
            writer.grab_frame()
    return png, gif
