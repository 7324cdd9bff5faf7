"""Fits from several initial guesses, and an honest account of what the data determine.

Two independent checks flag parameters the observation cannot pin down:

* **Curvature.** The Hessian of the loss in unconstrained coordinates (central
  differences of exact gradients) gives, through the Gauss-Newton relation
  cov(u) = 2 L / M H^-1 (L the mean squared residual, M the number of observed
  coordinates), a standard deviation per parameter. A parameter whose relative standard
  deviation exceeds :data:`RELATIVE_STD_LIMIT`, or a near-flat direction of the
  Hessian, is reported, naming the combination of parameters the data cannot resolve.
* **Restarts.** Fits from different initial guesses that reach equally low losses but
  disagree on a parameter show the same thing without any local approximation.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from taichi_mpm.materials import Material
from taichi_mpm.sysid import parameters
from taichi_mpm.sysid.fit import (
    FitError,
    FitResult,
    FitSettings,
    Objective,
    Progress,
    fit_reporting,
    resolve_settings,
)
from taichi_mpm.sysid.observation import Observation

RELATIVE_STD_LIMIT = 0.05  # a parameter known worse than 5% is not identified
FLAT_DIRECTION = 1e-6  # Hessian eigenvalue below this fraction of the largest: flat
RESTART_AGREEMENT = 0.05  # equally good restarts must agree to 5%
HESSIAN_STEP = 1e-3  # in unconstrained coordinates: 0.1% of E or of the yield stress


@dataclass
class Identification:
    """Result of :func:`identify`."""

    best: FitResult
    runs: list[FitResult]
    material: Material
    relative_std: dict[str, float]
    hessian: np.ndarray
    warnings: list[str] = field(default_factory=list)

    @property
    def identifiable(self) -> bool:
        return not self.warnings

    def summary(self) -> str:
        lines = [
            f"best loss {self.best.loss:.3e} after {self.best.iterations} iterations "
            f"({len(self.runs)} run{'s' if len(self.runs) > 1 else ''})"
        ]
        for name, value in self.best.values.items():
            std = self.relative_std.get(name, float("nan"))
            lines.append(f"  {name:<18} {value:12.5g}   +- {100 * std:.2g}%")
        if self.best.initial_velocity is not None:
            linear, angular = self.best.initial_velocity[:3], self.best.initial_velocity[3:]
            lines.append(
                f"  initial velocity   linear {np.round(linear, 4)} angular {np.round(angular, 4)}"
            )
        lines += [f"warning: {text}" for text in self.warnings] or ["all parameters identified"]
        return "\n".join(lines)


def identify(
    observation: Observation,
    material: Material,
    names: Sequence[str] | None = None,
    restarts: int = 1,
    seed: int = 0,
    settings: FitSettings | None = None,
    callback: Callable[[int, int, float, dict[str, float]], None] | None = None,
    verbose: bool = False,
    **options,
) -> Identification:
    """Fit from ``restarts`` initial guesses and report what the data determine.

    The first run starts from ``material``'s values; further runs start from guesses
    spread by up to a factor 3 around them (log-uniform, reproducible with ``seed``).
    ``settings`` and keyword ``options`` are those of :func:`~taichi_mpm.sysid.fit`;
    ``callback(run, iteration, loss, values)`` follows every run; ``verbose`` prints a line
    per step and per phase to stderr (these lines also go to the ``taichi_mpm.sysid`` logger
    at INFO level, silent unless logging is configured).
    """
    if restarts < 1:
        raise FitError(f"restarts={restarts} must be >= 1")
    settings = resolve_settings(settings, options)
    names = list(material.parameters() if names is None else names)
    rng = np.random.default_rng(seed)
    runs = []
    for run in range(restarts):
        start = material if run == 0 else _spread(material, names, rng)
        runs.append(
            fit_reporting(
                observation,
                start,
                names,
                settings,
                None if callback is None else _for_run(callback, run),
                Progress(verbose, f"run {run + 1}/{restarts}: " if restarts > 1 else ""),
            )
        )
    best = min(runs, key=lambda r: r.loss)
    fitted = material.replace(**best.values)
    size = len(names) + (6 if best.initial_velocity is not None else 0)
    Progress(verbose)(f"uncertainties: {2 * size} simulations around the best fit")
    relative_std, hessian, warnings = _curvature(observation, fitted, names, best)
    if not best.converged:
        warnings.insert(
            0,
            f"the best fit stopped after {best.iterations} iterations without converging; "
            "its values may be inaccurate: raise --iterations or use the lbfgs optimizer",
        )
    warnings += _restart_disagreement(runs, best, names)
    return Identification(best, runs, fitted, relative_std, hessian, warnings)


def _for_run(callback, run: int):
    return lambda iteration, loss, values: callback(run, iteration, loss, values)


def _spread(material: Material, names: list[str], rng) -> Material:
    """The material with each fitted parameter moved by a random factor in [1/3, 3]."""
    current = material.parameters()
    spread = {}
    for name in names:
        transform = parameters.TRANSFORMS[name]
        value = current[name] * np.exp(rng.uniform(-np.log(3.0), np.log(3.0)))
        if np.isfinite(transform.high):  # stay inside a bounded range
            margin = 1e-3 * (transform.high - transform.low)
            value = min(max(value, transform.low + margin), transform.high - margin)
        spread[name] = float(value)
    return material.replace(**spread)


VELOCITY_NAMES = [f"{kind}_velocity_{axis}" for kind in ("linear", "angular") for axis in "xyz"]


def _curvature(observation: Observation, fitted: Material, names: list[str], best: FitResult):
    """Relative standard deviations, the Hessian, and warnings from the loss curvature.

    With a fitted initial velocity the Hessian covers it too, so the material's
    uncertainty includes what the unknown velocity leaves open.
    """
    if not names:
        return {}, np.zeros((0, 0)), []
    velocity = best.initial_velocity
    objective = Objective(observation, fitted, names, fit_velocity=velocity is not None)
    u0 = parameters.to_unconstrained({name: best.values[name] for name in names})
    labels = list(names)
    if velocity is not None:
        u0 = np.concatenate([u0, velocity])
        labels += VELOCITY_NAMES
    n = len(u0)
    hessian = np.zeros((n, n))
    for i in range(n):
        step = np.zeros(n)
        step[i] = HESSIAN_STEP
        _, up = objective(u0 + step)
        _, down = objective(u0 - step)
        if up is None or down is None:
            return (
                {name: float("nan") for name in names},
                hessian,
                ["the simulation is unstable next to the fitted values; uncertainties unknown"],
            )
        hessian[:, i] = (up - down) / (2 * HESSIAN_STEP)
    hessian = 0.5 * (hessian + hessian.T)
    eigenvalues, eigenvectors = np.linalg.eigh(hessian)
    scale = max(abs(eigenvalues).max(), 1e-300)
    flat = np.abs(eigenvalues) <= FLAT_DIRECTION * scale
    warnings = []
    if (eigenvalues < -FLAT_DIRECTION * scale).any():
        warnings.append(
            "the loss still curves downwards at the fitted values: the fit has not "
            "converged; run more iterations, another optimizer or more restarts"
        )
    # Gauss-Newton covariance of u; a flat direction has unbounded variance.
    noise = 2.0 * max(best.loss, 1e-30) / observation.positions.size
    weights = eigenvectors**2  # weights[i, k]: share of coordinate i in direction k
    usable = ~flat & (eigenvalues > 0)
    inverse = np.where(usable, 1.0 / np.where(usable, eigenvalues, 1.0), np.inf)
    involved = weights > 1e-6
    contributions = np.zeros_like(weights)
    contributions[involved] = weights[involved] * np.broadcast_to(inverse, weights.shape)[involved]
    variance_u = noise * contributions.sum(axis=1)
    relative_std = {}
    for i, name in enumerate(names):
        slope = parameters.TRANSFORMS[name].derivative(u0[i])
        relative_std[name] = (
            slope * float(np.sqrt(variance_u[i])) / max(abs(best.values[name]), 1e-300)
        )
    flagged: set[str] = set()  # parameters already named by a flat-direction warning
    for vector in eigenvectors.T[flat]:
        involved_names = [labels[i] for i in np.argsort(-np.abs(vector)) if abs(vector[i]) > 0.2]
        flagged.update(involved_names)
        if len(involved_names) == 1:
            warnings.append(
                f"the observation does not depend on {involved_names[0]}: it cannot be "
                "identified from these data"
            )
        else:
            warnings.append(
                "the observation does not change when "
                + " and ".join(involved_names)
                + " change together (a flat direction of the loss): they cannot be "
                "separated, only a combination of them is determined"
            )
    for name, std in relative_std.items():
        if name not in flagged and (not np.isfinite(std) or std > RELATIVE_STD_LIMIT):
            warnings.append(
                f"{name} is poorly determined (estimated relative standard deviation "
                f"{100 * std:.3g}%)"
            )
    return relative_std, hessian, warnings


def _restart_disagreement(runs: list[FitResult], best: FitResult, names: list[str]) -> list[str]:
    good = [run for run in runs if run.loss <= 1.5 * best.loss + 1e-14]
    if len(good) < 2:
        return []
    warnings = []
    for name in names:
        values = np.array([run.values[name] for run in good])
        spread = (values.max() - values.min()) / max(abs(np.median(values)), 1e-300)
        if spread > RESTART_AGREEMENT:
            warnings.append(
                f"{len(good)} restarts reach the same loss but disagree on {name} "
                f"({values.min():.4g} to {values.max():.4g})"
            )
    return warnings
