"""The text a constitutive-law evaluation reports back to the model.

Three parts, as the method asks for: how the loss evolved during the inner optimization (and
its best value), how each fitted parameter evolved (and its value at the best epoch), and where
a few representative particles (corners of the body) went, simulated versus observed, at about
ten moments of the trajectory. Of those positions only the ones that disagree most are listed,
with their errors; the others are summed up in one line (once a law fits, all of them agree
and the table would only repeat the observation).
"""

from __future__ import annotations

import numpy as np

from taichi_mpm.frames import evenly_spaced
from tasks.constitutive.inner import InnerResult, InnerSettings

CURVE_POINTS = 10  # values listed per curve
TRAJECTORY_FRAMES = 10
CORNERS = 4  # particles followed
TRAJECTORY_ROWS = 8  # (particle, moment) rows listed at most; the others get one line
PRINTED = 1e-3  # m: positions are printed to the mm, so a smaller error shows as none
PARAMETERS_LISTED = 16  # scalar parameter values listed; a larger law gets a count


def corner_particles(positions: np.ndarray, count: int = CORNERS) -> list[int]:
    """Indices of particles at alternating corners of the body's bounding box."""
    signs = [(-1, -1, -1), (1, 1, -1), (1, -1, 1), (-1, 1, 1),
             (1, -1, -1), (-1, 1, -1), (-1, -1, 1), (1, 1, 1)]  # fmt: skip
    centred = positions - positions.mean(axis=0)
    return [int(np.argmax(centred @ np.array(sign, float))) for sign in signs[:count]]


def listed_epochs(epochs: int, best: int, points: int = CURVE_POINTS) -> list[int]:
    """The epochs a curve lists: every one when there are ``points`` or fewer, else ``points``
    evenly spread from the first to the last, and always the ``best`` one (the feedback names
    its value, so the list must show it).

    >>> listed_epochs(30, 25)
    [0, 3, 6, 10, 13, 16, 19, 23, 25, 26, 29]
    """
    if epochs <= points:
        return list(range(epochs))
    picks = {int(i) for i in evenly_spaced(0, epochs - 1, points)}
    if 0 <= best < epochs:
        picks.add(best)
    return sorted(picks)


def _curve(values: list[float], epochs: list[int]) -> str:
    return ", ".join(f"{i}: {values[i]:.4g}" for i in epochs if i < len(values))


#: What the loss of the constitutive tasks is, as the feedback names it.
LOSS = "mean squared position error over all steps, m^2"


def optimization_text(result: InnerResult, settings: InnerSettings, loss: str = LOSS) -> str:
    """Loss and parameter curves with their best values; ``loss`` says what the loss is."""
    epochs = len(result.losses)
    listed = listed_epochs(epochs, result.best_epoch)
    lines = []
    if not result.parameters:
        lines.append(
            f"The law has no trainable parameters; it was simulated once. Loss ({loss}): "
            f"{result.best_loss:.6g}."
        )
    else:
        lines += [
            f"Inner optimization: {_optimizer(settings)} over {epochs} "
            f"{'evaluation' if epochs == 1 else 'evaluations'} of the whole trajectory.",
            f"Loss ({loss}), by epoch: {_curve(result.losses, listed)}",
            f"Best loss {result.best_loss:.6g} at epoch {result.best_epoch}.",
            "Parameters by epoch (the value at the best epoch is kept):",
        ]
        best = result.best_parameters
        for name, values in list(result.parameters.items())[:PARAMETERS_LISTED]:
            lines.append(f"- {name}: {_curve(values, listed)}; best {best[name]:.6g}")
        hidden = len(result.parameters) - PARAMETERS_LISTED
        if hidden > 0:
            noun = "value" if hidden == 1 else "values"
            lines.append(f"- ... and {hidden} more parameter {noun} (not listed)")
    if rejected := len(result.rejected_trials):
        points, were = ("trial point", "was") if rejected == 1 else ("trial points", "were")
        lines.append(
            f"{rejected} {points} of the line search {were} rejected (not among the epochs "
            f"above), the first at {result.rejected_trials[0]}."
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
    """Positions of ``particles`` at ~10 moments, simulated next to observed: the rows that
    disagree most (see :func:`position_table`)."""
    steps = observed.shape[0] - 1
    frames = evenly_spaced(0, steps, TRAJECTORY_FRAMES + 1)[1:]
    return position_table(
        "Trajectories of corner particles (x, y, z in m; y points up), simulated vs observed",
        observed[0, particles],
        [frame * dt for frame in frames],
        predicted[np.ix_(frames, particles)].swapaxes(0, 1),
        observed[np.ix_(frames, particles)].swapaxes(0, 1),
    )


def position_table(
    title: str, starts: np.ndarray, times: list[float], simulated: np.ndarray,
    observed: np.ndarray, rows: int = TRAJECTORY_ROWS,
) -> str:  # fmt: skip
    """``title`` and the rows (particle, moment) that say something: at most ``rows`` of those
    whose simulated position is off the observed one by :data:`PRINTED` or more, the largest
    errors, listed in particle and time order, then one line for the rest; one line when all
    agree. ``simulated`` and ``observed`` are (particles, moments, 3), ``starts`` (particles, 3).
    """
    errors = np.linalg.norm(simulated - observed, axis=-1)
    errors = np.where(np.isnan(errors), np.inf, errors)  # a non-finite position disagrees most
    total = errors.size
    worst = [int(k) for k in np.argsort(-errors, axis=None, kind="stable")[:rows]]
    kept = sorted(k for k in worst if errors.flat[k] >= PRINTED)
    shown = f"{len(starts)} particles at {len(times)} moments"
    if not kept:
        return (
            f"{title} ({shown}): all {total} positions agree to within the printed precision "
            f"({_mm(PRINTED)}); largest error {_mm(errors.max())}."
        )
    lines = [f"{title}, the {len(kept)} of {total} rows ({shown}) with the largest errors:"]
    for number in dict.fromkeys(k // len(times) for k in kept):
        lines.append(f"Particle {number} (starts at {_xyz(starts[number])}):")
        for k in kept:
            if k // len(times) == number:
                moment = k % len(times)
                lines.append(
                    f"  t = {times[moment]:.3f} s: simulated {_xyz(simulated[number, moment])}, "
                    f"observed {_xyz(observed[number, moment])}, error {_mm(errors.flat[k])}"
                )
    if total > len(kept):
        rest = np.delete(errors.reshape(-1), kept)
        summary = f"agree to within {_mm(rest.max())} (their largest error)"
        if not np.isfinite(rest.max()):
            summary = "hold non-finite positions too"
        lines.append(f"The other {rest.size} rows {summary}.")
    return "\n".join(lines)


def _mm(metres: float) -> str:
    return f"{metres * 1e3:.1f} mm" if np.isfinite(metres) else "a non-finite distance"


def _xyz(point: np.ndarray) -> str:
    return "(" + ", ".join(f"{c:.3f}" for c in point) + ")"
