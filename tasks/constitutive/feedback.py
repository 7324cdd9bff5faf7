"""The text a constitutive-law evaluation reports back to the model.

Three parts, as the method asks for: how the loss evolved during the inner optimization (and
its best value), how each fitted parameter evolved (and its value at the best epoch), and where
a few representative particles (corners of the body) went, simulated versus observed, at about
ten moments of the trajectory.
"""

from __future__ import annotations

import numpy as np

from taichi_mpm.frames import evenly_spaced
from tasks.constitutive.inner import InnerResult, InnerSettings

CURVE_POINTS = 10  # values listed per curve
TRAJECTORY_FRAMES = 10
CORNERS = 4  # particles listed
PARAMETERS_LISTED = 16  # scalar parameter values listed; a larger law gets a count


def corner_particles(positions: np.ndarray, count: int = CORNERS) -> list[int]:
    """Indices of particles at alternating corners of the body's bounding box."""
    signs = [(-1, -1, -1), (1, 1, -1), (1, -1, 1), (-1, 1, 1),
             (1, -1, -1), (-1, 1, -1), (-1, -1, 1), (1, 1, 1)]  # fmt: skip
    centred = positions - positions.mean(axis=0)
    return [int(np.argmax(centred @ np.array(sign, float))) for sign in signs[:count]]


def _sampled(values: list[float], points: int = CURVE_POINTS) -> list[tuple[int, float]]:
    if len(values) <= points:
        return list(enumerate(values))
    picks = evenly_spaced(0, len(values) - 1, points)
    return [(int(i), values[i]) for i in picks]


def _curve(values: list[float]) -> str:
    return ", ".join(f"{i}: {value:.4g}" for i, value in _sampled(values))


#: What the loss of the constitutive tasks is, as the feedback names it.
LOSS = "mean squared position error over all steps, m^2"


def optimization_text(result: InnerResult, settings: InnerSettings, loss: str = LOSS) -> str:
    """Loss and parameter curves with their best values; ``loss`` says what the loss is."""
    epochs = len(result.losses)
    lines = []
    if not result.parameters:
        lines.append(
            f"The law has no trainable parameters; it was simulated once. Loss ({loss}): "
            f"{result.best_loss:.6g}."
        )
    else:
        lines += [
            f"Inner optimization: {_optimizer(settings)} over {epochs} evaluations of the "
            "whole trajectory.",
            f"Loss ({loss}), by epoch: "
            f"{_curve(result.losses)}",
            f"Best loss {result.best_loss:.6g} at epoch {result.best_epoch}.",
            "Parameters by epoch (the value at the best epoch is kept):",
        ]
        best = result.best_parameters
        for name, values in list(result.parameters.items())[:PARAMETERS_LISTED]:
            lines.append(f"- {name}: {_curve(values)}; best {best[name]:.6g}")
        hidden = len(result.parameters) - PARAMETERS_LISTED
        if hidden > 0:
            lines.append(f"- ... and {hidden} more parameter values (not listed)")
    if result.rejected_trials:
        lines.append(
            f"{len(result.rejected_trials)} trial points of the line search were rejected (not "
            f"among the epochs above), the first at {result.rejected_trials[0]}."
        )
    if result.stopped:
        lines.append(f"The optimization stopped early at {result.stopped}.")
    if result.unused:
        lines.append(unused_text(result.unused))
    return "\n".join(lines)


def unused_text(names: list[str]) -> str:
    """One sentence naming the parameters the loss does not depend on."""
    listed = ", ".join(names)
    if len(names) == 1:
        return (
            f"The loss does not depend on the parameter {listed} (no gradient reaches it from "
            "the law's output), so it was not fitted: use it in forward or remove it."
        )
    return (
        f"The loss does not depend on the parameters {listed} (no gradient reaches them from "
        "the law's output), so they were not fitted: use them in forward or remove them."
    )


def _optimizer(settings: InnerSettings) -> str:
    if settings.optimizer == "lbfgs":
        return "L-BFGS with a line search (several evaluations may share one step)"
    return f"Adam (learning rate {settings.learning_rate:g})"


def trajectory_text(
    predicted: np.ndarray, observed: np.ndarray, dt: float, particles: list[int]
) -> str:
    """Positions of ``particles`` at ~10 moments, simulated next to observed."""
    steps = observed.shape[0] - 1
    frames = evenly_spaced(0, steps, TRAJECTORY_FRAMES + 1)[1:]
    lines = ["Trajectories of corner particles (x, y, z in m; y points up), simulated vs observed:"]
    for number, particle in enumerate(particles):
        start = observed[0, particle]
        lines.append(f"Particle {number} (starts at {_xyz(start)}):")
        for frame in frames:
            sim, obs = predicted[frame, particle], observed[frame, particle]
            lines.append(f"  t = {frame * dt:.3f} s: simulated {_xyz(sim)}, observed {_xyz(obs)}")
    return "\n".join(lines)


def _xyz(point: np.ndarray) -> str:
    return "(" + ", ".join(f"{c:.3f}" for c in point) + ")"
