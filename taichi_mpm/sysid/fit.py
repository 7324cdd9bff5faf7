"""Fit material parameters to an observed trajectory through the differentiable simulator."""

from __future__ import annotations

import logging
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields, replace

import numpy as np

from taichi_mpm.materials import Material
from taichi_mpm.scene import rigid_velocity, rigid_velocity_gradient
from taichi_mpm.simulator import Simulator
from taichi_mpm.sysid import parameters
from taichi_mpm.sysid.observation import Observation

OPTIMIZERS = ("adam", "lbfgs")
PLATEAU_CUTS = 3  # Adam: step cuts on plateaus before it stops
MAX_BACKOFFS = 20  # steps undone because the simulation blew up, before giving up
LINE_SEARCH_HALVINGS = 10  # L-BFGS: below 2^-10 of the step, no descent is left

log = logging.getLogger("taichi_mpm.sysid")


class Progress:
    """Where a fit's progress lines go: always to the ``taichi_mpm.sysid`` logger at INFO
    (silent unless logging is configured), and to stderr as well when ``verbose``."""

    def __init__(self, verbose: bool = False, prefix: str = "") -> None:
        self.verbose, self.prefix = verbose, prefix

    def __call__(self, message: str) -> None:
        log.info("%s%s", self.prefix, message)
        if self.verbose:
            print(f"{self.prefix}{message}", file=sys.stderr, flush=True)

    def iteration(self, iteration: int, loss: float, values: dict[str, float]) -> None:
        shown = "".join(f", {name} {value:.5g}" for name, value in values.items())
        self(f"iteration {iteration}: loss {loss:.4e}{shown}")


class FitError(ValueError):
    """A fit was set up wrongly; the message names the argument and the fix."""


@dataclass
class FitResult:
    """One fit: the values found, and how the optimizer got there."""

    values: dict[str, float]
    loss: float
    loss_curve: list[float]
    history: dict[str, list[float]]
    iterations: int
    converged: bool
    backoffs: int = 0
    initial_velocity: np.ndarray | None = None  # (linear, angular) when fitted
    gradient_norm: float = float("nan")


@dataclass
class Objective:
    """Loss and gradient in unconstrained coordinates u, one simulation each."""

    observation: Observation
    material: Material
    names: list[str]
    fit_velocity: bool = False
    checkpoint_every: int | None = None
    evaluations: int = field(default=0, init=False)

    def __post_init__(self) -> None:
        self._sim = Simulator(self.observation.scene, self.material, self.checkpoint_every)
        self._scale = 1.0 / (self.observation.positions.size * self.observation.body_size**2)

    @property
    def size(self) -> int:
        return len(self.names) + (6 if self.fit_velocity else 0)

    def split(self, u: np.ndarray):
        n = len(self.names)
        return u[:n], (u[n : n + 3], u[n + 3 : n + 6]) if self.fit_velocity else None

    def __call__(self, u: np.ndarray) -> tuple[float, np.ndarray | None]:
        """(loss, dloss/du); (inf, None) when the simulation blows up."""
        self.evaluations += 1
        obs = self.observation
        material_u, velocity = self.split(u)
        values = parameters.to_values(self.names, material_u)
        try:
            self._sim.material = self.material.replace(**values)
        except ValueError:
            return float("inf"), None
        if velocity is not None:
            self._sim.scene = obs.scene.with_velocities(
                rigid_velocity(obs.scene.positions, velocity[0], velocity[1])
            )
        simulated = self._sim.forward(obs.frame_steps)[:, obs.particle_indices]
        residual = simulated - obs.positions
        loss = float(self._scale * (residual**2).sum())
        if not np.isfinite(loss):
            return float("inf"), None
        seed = np.zeros((len(obs.frame_steps), obs.scene.num_particles, 3))
        seed[:, obs.particle_indices] = 2.0 * self._scale * residual
        grads = self._sim.backward(seed)
        grad_u = parameters.chain(self.names, material_u, grads.material)
        if velocity is not None:
            d_linear, d_angular = rigid_velocity_gradient(obs.scene.positions, grads.velocities)
            grad_u = np.concatenate([grad_u, d_linear, d_angular])
        if not np.all(np.isfinite(grad_u)):
            return float("inf"), None
        return loss, grad_u


@dataclass(frozen=True)
class FitSettings:
    """How :func:`fit` optimizes; checked on construction.

    Parameters
    ----------
    optimizer : {"adam", "lbfgs"}
        Adam with ``learning_rate`` in unconstrained coordinates, or L-BFGS with a
        backtracking line search whose first step moves by ``learning_rate``.
    iterations : int
        Most optimizer steps.
    learning_rate : float
        Step size in unconstrained coordinates (0.05 = 5% of E or of the yield stress).
    tolerance : float
        A plateau is a best loss that improved by less than ``tolerance`` (relative) over
        ``patience`` steps: L-BFGS stops there, Adam cuts its step and stops at the
        fourth plateau.
    patience : int
        Length, in optimizer steps, of the window of that plateau rule (see ``tolerance``).
    fit_velocity : bool
        Also fit the initial linear and angular velocity of the body (a rigid motion),
        starting from ``initial_velocity`` (default: at rest).
    checkpoint_every : int, optional
        Passed to the :class:`~taichi_mpm.Simulator`.
    """

    optimizer: str = "adam"
    iterations: int = 200
    learning_rate: float = 0.05
    tolerance: float = 1e-4
    patience: int = 10
    fit_velocity: bool = False
    initial_velocity: tuple[Sequence[float], Sequence[float]] | None = None
    checkpoint_every: int | None = None

    def __post_init__(self) -> None:
        if self.optimizer not in OPTIMIZERS:
            raise FitError(f"optimizer={self.optimizer!r} is unknown; use one of {OPTIMIZERS}")
        if self.iterations < 1 or self.patience < 1:
            raise FitError(
                f"iterations={self.iterations} and patience={self.patience} must be >= 1"
            )
        if not self.learning_rate > 0:
            raise FitError(f"learning_rate={self.learning_rate} must be > 0")


def fit(
    observation: Observation,
    material: Material,
    names: Sequence[str] | None = None,
    settings: FitSettings | None = None,
    callback: Callable[[int, float, dict[str, float]], None] | None = None,
    verbose: bool = False,
    **options,
) -> FitResult:
    """Fit ``names`` (default: all parameters of ``material``) to ``observation``.

    Parameters
    ----------
    observation : Observation
        Observed positions and the scene they come from.
    material : Material
        The material family with initial guesses for its parameters.
    names : sequence of str, optional
        Parameters to fit; the others stay at their values in ``material``.
    settings : FitSettings, optional
        The optimizer and its stopping rule; keyword ``options`` (``optimizer="lbfgs"``,
        ``learning_rate=0.5``, ...) build or override it.
    callback : callable, optional
        Called as ``callback(iteration, loss, values)`` after every step.
    verbose : bool
        Print a line per step (its loss and values) to stderr. Either way these lines go to
        the ``taichi_mpm.sysid`` logger at INFO level, which prints nothing unless logging is
        configured (``logging.basicConfig(level=logging.INFO)``).
    """
    settings = resolve_settings(settings, options)
    return fit_reporting(observation, material, names, settings, callback, Progress(verbose))


def fit_reporting(
    observation: Observation,
    material: Material,
    names: Sequence[str] | None,
    settings: FitSettings,
    callback: Callable[[int, float, dict[str, float]], None] | None,
    progress: Progress,
) -> FitResult:
    """:func:`fit` with its progress lines going to ``progress``."""
    available = material.parameters()
    names = list(available if names is None else names)
    unknown = [name for name in names if name not in available]
    if unknown:
        raise FitError(f"cannot fit {unknown}: this material has parameters {sorted(available)}")
    if not names and not settings.fit_velocity:
        raise FitError("nothing to fit: give parameter names or fit_velocity=True")
    for name in names:
        transform = parameters.TRANSFORMS[name]
        if not transform.contains(available[name]):
            raise FitError(
                f"{name}={available[name]} is on the edge of its range "
                f"({transform.low}, {transform.high}); start from a value inside it "
                f"(for example {name}=1e-3) or leave {name} out of the fitted names"
            )
    objective = Objective(
        observation, material, names, settings.fit_velocity, settings.checkpoint_every
    )
    u = parameters.to_unconstrained({name: available[name] for name in names})
    if settings.fit_velocity:
        start = settings.initial_velocity or ((0.0,) * 3, (0.0,) * 3)
        u = np.concatenate([u, np.asarray(start[0], float), np.asarray(start[1], float)])
    progress(
        f"fitting {', '.join(names + (['initial velocity'] if settings.fit_velocity else []))} "
        f"with {settings.optimizer}, at most {settings.iterations} iterations (the first one "
        "compiles the simulator's kernels)"
    )
    step = _adam if settings.optimizer == "adam" else _lbfgs
    result = step(
        objective,
        u,
        settings.iterations,
        settings.learning_rate,
        settings.tolerance,
        settings.patience,
        _reporting(callback, progress),
    )
    ending = "converged" if result.converged else "stopped without converging"
    progress(f"{ending} after {result.iterations} iterations: loss {result.loss:.4e}")
    return result


def _reporting(callback, progress: Progress):
    """``callback`` preceded by the progress line of each step."""

    def report(iteration: int, loss: float, values: dict[str, float]) -> None:
        progress.iteration(iteration, loss, values)
        if callback is not None:
            callback(iteration, loss, values)

    return report


def resolve_settings(settings: FitSettings | None, options: dict) -> FitSettings:
    """``settings`` with keyword overrides; unknown keywords name the valid ones."""
    valid = {f.name for f in fields(FitSettings)}
    unknown = sorted(set(options) - valid)
    if unknown:
        raise FitError(f"unknown fit option(s) {unknown}; valid: {sorted(valid)}")
    return replace(settings or FitSettings(), **options)


class _Tracker:
    """Loss curve, parameter history, best point and the stopping rule."""

    def __init__(self, objective: Objective, tolerance: float, patience: int, callback) -> None:
        self.objective, self.tolerance, self.patience = objective, tolerance, patience
        self.callback = callback
        self.curve: list[float] = []
        self.history: dict[str, list[float]] = {name: [] for name in objective.names}
        self.best = (float("inf"), None, None)
        self.backoffs = 0
        self.window_start = 0  # plateaus are judged on iterations from here on
        self.stalled = False  # set when no step can lower the loss any more

    def record(self, u: np.ndarray, loss: float, grad: np.ndarray) -> None:
        values = parameters.to_values(self.objective.names, self.objective.split(u)[0])
        self.curve.append(loss)
        for name, value in values.items():
            self.history[name].append(value)
        if loss < self.best[0]:
            self.best = (loss, u.copy(), grad)
        if self.callback is not None:
            self.callback(len(self.curve), loss, values)

    def plateau(self) -> bool:
        """The best loss improved by less than ``tolerance`` over ``patience`` iterations."""
        window = self.curve[self.window_start :]
        if len(window) <= self.patience:
            return False
        before = min(window[: -self.patience])
        return before - self.best[0] <= self.tolerance * before

    def converged(self) -> bool:
        return self.stalled or self.plateau()

    def result(self) -> FitResult:
        loss, u, grad = self.best
        material_u, velocity = self.objective.split(u)
        return FitResult(
            values=parameters.to_values(self.objective.names, material_u),
            loss=loss,
            loss_curve=self.curve,
            history=self.history,
            iterations=len(self.curve),
            converged=self.converged(),
            backoffs=self.backoffs,
            initial_velocity=None if velocity is None else np.concatenate(velocity),
            gradient_norm=float(np.linalg.norm(grad)),
        )


def _first_evaluation(objective: Objective, u: np.ndarray) -> tuple[float, np.ndarray]:
    loss, grad = objective(u)
    if grad is None:
        raise FitError(
            "the simulation diverges at the initial guess (NaN positions); start from a "
            "softer material, a smaller dt or a smaller initial velocity"
        )
    return loss, grad


def _adam(objective, u, iterations, lr, tolerance, patience, callback) -> FitResult:
    """Adam; on a plateau it restarts from the best point with a 3x smaller step, and
    stops once the step has been cut :data:`PLATEAU_CUTS` times."""
    tracker = _Tracker(objective, tolerance, patience, callback)
    loss, grad = _first_evaluation(objective, u)
    tracker.record(u, loss, grad)
    m, v = np.zeros_like(u), np.zeros_like(u)
    beta1, beta2, eps = 0.9, 0.999, 1e-8
    t, cuts = 0, 0
    while len(tracker.curve) < iterations:
        if tracker.plateau():
            if cuts == PLATEAU_CUTS:
                break
            cuts += 1
            lr /= 3.0
            _, best_u, best_grad = tracker.best
            u, grad = best_u.copy(), best_grad
            m[:], v[:], t = 0.0, 0.0, 0
            tracker.window_start = len(tracker.curve)
        t += 1
        m = beta1 * m + (1 - beta1) * grad
        v = beta2 * v + (1 - beta2) * grad**2
        trial = u - lr * (m / (1 - beta1**t)) / (np.sqrt(v / (1 - beta2**t)) + eps)
        trial_loss, trial_grad = objective(trial)
        if trial_grad is None:  # unstable: back off, keep the last good point
            lr *= 0.5
            tracker.backoffs += 1
            m[:], v[:], t = 0.0, 0.0, 0
            if tracker.backoffs > MAX_BACKOFFS:
                break
            continue
        u, loss, grad = trial, trial_loss, trial_grad
        tracker.record(u, loss, grad)
    return tracker.result()


def _lbfgs(objective, u, iterations, lr, tolerance, patience, callback, memory=8) -> FitResult:
    tracker = _Tracker(objective, tolerance, patience, callback)
    loss, grad = _first_evaluation(objective, u)
    tracker.record(u, loss, grad)
    s_list: list[np.ndarray] = []
    y_list: list[np.ndarray] = []
    while len(tracker.curve) < iterations and not tracker.plateau():
        direction = -_two_loop(grad, s_list, y_list)
        if direction @ grad >= 0:  # not a descent direction: restart from the gradient
            s_list.clear()
            y_list.clear()
            direction = -grad
        # Without curvature pairs yet, the first step moves u by ``lr`` at most.
        step = 1.0 if s_list else lr / (np.abs(direction).max() + 1e-300)
        for _ in range(LINE_SEARCH_HALVINGS):  # backtracking (Armijo) line search
            trial = u + step * direction
            trial_loss, trial_grad = objective(trial)
            if trial_grad is not None and trial_loss <= loss + 1e-4 * step * (direction @ grad):
                break
            step *= 0.5
            tracker.backoffs += trial_grad is None
        else:  # no decrease along a descent direction: the loss is at its floor
            tracker.stalled = True
            break
        s, y = trial - u, trial_grad - grad
        if s @ y > 1e-12 * np.linalg.norm(s) * np.linalg.norm(y):
            s_list.append(s)
            y_list.append(y)
            del s_list[:-memory], y_list[:-memory]
        u, loss, grad = trial, trial_loss, trial_grad
        tracker.record(u, loss, grad)
    return tracker.result()


def _two_loop(grad: np.ndarray, s_list, y_list) -> np.ndarray:
    """L-BFGS estimate of H^-1 grad."""
    q = grad.copy()
    alphas = []
    for s, y in zip(reversed(s_list), reversed(y_list), strict=True):
        alpha = (s @ q) / (y @ s)
        alphas.append(alpha)
        q -= alpha * y
    if s_list:
        q *= (s_list[-1] @ y_list[-1]) / (y_list[-1] @ y_list[-1])
    for (s, y), alpha in zip(zip(s_list, y_list, strict=True), reversed(alphas), strict=True):
        q += (alpha - (y @ q) / (y @ s)) * s
    return q
