"""``taichi-mpm sysid``: fit material parameters to an observed motion."""

from __future__ import annotations

import json
import logging
import re
import time
from collections.abc import Callable
from pathlib import Path

import click
import numpy as np
from rich.console import Console

import taichi_mpm as tm
from taichi_mpm.cli import arch_option, main, precision_option, start_taichi
from taichi_mpm.cli.heartbeat import Heartbeat
from taichi_mpm.sysid.families import (
    FAMILIES,
    family_parameters,
    material_family,
    parse_assignment,
)

_SYSID_HELP = (
    "Fit material parameters to an observed motion (system identification).\n\n"
    "OBSERVED is an observation .npz (see taichi_mpm.sysid.observation; "
    "scripts/make_observation.py writes synthetic ones). The material families are:\n\n\b\n"
    + "\n".join(f"  {name:<11} {text}" for name, text in FAMILIES.items())
    + "\n\nWrites fit.json (values, loss curve, history, warnings, relative standard "
    "deviations) and comparison.png (observed vs fitted particles, loss curve) to --out-dir. "
    "While it works it shows its progress (each iteration's loss and values): a bar on a "
    "terminal, else, from 5 s on, a plain line on stderr every 5 s."
)

#: The logger of the fits' progress lines (:class:`taichi_mpm.sysid.fit.Progress`).
FIT_LOGGER = "taichi_mpm.sysid"
#: A line of the fit logger for one iteration ("run 2/3: iteration 5: loss ...").
_ITERATION = re.compile(r"(run \d+/\d+: )?iteration \d+:")


def iteration_text(
    run: int, runs: int, iteration: int, iterations: int, loss: float, values: dict[str, float]
) -> str:
    """One iteration of the fit in words: "fitting: iteration 7/200, loss 0.0001227,
    yield_stress=1977" (with "run 2/3, " before the iteration when there are several runs)."""
    shown = "".join(f", {name}={value:.4g}" for name, value in values.items())
    which = f"run {run + 1}/{runs}, " if runs > 1 else ""
    return f"fitting: {which}iteration {iteration}/{iterations}, loss {loss:.4g}{shown}"


class FitPhases(logging.Handler):
    """Tells ``show`` each phase the fits log (the start of a run, its end, the uncertainties'
    simulations), not their iterations (the callback tells those, counted), while it is used as
    a context manager: the fit logger then logs at INFO level at least."""

    def __init__(self, show: Callable[[str], None]) -> None:
        super().__init__(logging.INFO)
        self.show = show
        self.logger = logging.getLogger(FIT_LOGGER)
        self.level_before = self.logger.level

    def __enter__(self) -> FitPhases:
        self.level_before = self.logger.level
        if not self.logger.isEnabledFor(logging.INFO):
            self.logger.setLevel(logging.INFO)
        self.logger.addHandler(self)
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.logger.removeHandler(self)
        self.logger.setLevel(self.level_before)

    def emit(self, record: logging.LogRecord) -> None:
        message = record.getMessage()
        if not _ITERATION.match(message):
            self.show(message)


def _parse_guesses(ctx, param, values) -> dict[str, float]:
    """--guess NAME=VALUE ... -> {name: value}; malformed text is a usage error."""
    guesses: dict[str, float] = {}
    for text in values:
        try:
            name, value = parse_assignment(text)
        except ValueError as error:
            raise click.BadParameter(str(error), ctx=ctx, param=param) from None
        guesses[name] = value
    return guesses


def _json_ready(value):
    """Numbers, arrays and containers as JSON values; NaN and inf become null."""
    if isinstance(value, dict):
        return {str(k): _json_ready(v) for k, v in value.items()}
    if isinstance(value, list | tuple | np.ndarray):
        return [_json_ready(v) for v in value]
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value) if np.isfinite(value) else None
    return value


@main.command(help=_SYSID_HELP)
@click.argument("observed", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "--material",
    "family",
    type=click.Choice(tuple(FAMILIES), case_sensitive=False),
    required=True,
    help="Material family to fit.",
)
@click.option(
    "--fit",
    "names",
    multiple=True,
    metavar="NAME",
    help="A parameter to fit (repeatable). Default: all parameters of the family.",
)
@click.option(
    "--guess",
    multiple=True,
    metavar="NAME=VALUE",
    callback=_parse_guesses,
    help="Initial guess of a parameter (repeatable); the others start at the family's "
    "defaults. Parameters not fitted stay at these values.",
)
@click.option(
    "--optimizer",
    type=click.Choice(("adam", "lbfgs")),
    default="adam",
    show_default=True,
    help="Adam, or L-BFGS with a backtracking line search.",
)
@click.option(
    "--restarts",
    type=click.IntRange(min=1),
    default=1,
    show_default=True,
    help="Fits from different initial guesses (the first from --guess, the others spread "
    "around it).",
)
@click.option(
    "--iterations",
    type=click.IntRange(min=1),
    default=200,
    show_default=True,
    help="Most optimizer steps per run.",
)
@click.option(
    "--lr",
    "learning_rate",
    type=click.FloatRange(min=0.0, min_open=True),
    default=0.05,
    show_default=True,
    help="Learning rate (Adam) or first step (L-BFGS), in log-parameter units.",
)
@click.option(
    "--fit-velocity",
    is_flag=True,
    help="Also fit the body's initial linear and angular velocity, starting from the rigid "
    "motion closest to the file's initial velocities.",
)
@click.option(
    "--seed", type=int, default=0, show_default=True, help="Seed of the restarts' guesses."
)
@click.option(
    "--out-dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("sysid_out"),
    show_default=True,
    help="Folder for fit.json and comparison.png (created if missing).",
)
@arch_option
@precision_option
def sysid(
    observed: Path,
    family: str,
    names: tuple[str, ...],
    guess: dict[str, float],
    restarts: int,
    seed: int,
    out_dir: Path,
    arch: str,
    precision: str,
    **fit,
) -> None:
    """``fit``: the options that set the :class:`~taichi_mpm.sysid.FitSettings` (--optimizer,
    --iterations, --lr, --fit-velocity)."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
    from rich.table import Column

    from taichi_mpm.sysid import FitError, FitSettings, ObservationError, identify, load_observation
    from taichi_mpm.sysid.parameters import TRANSFORMS
    from taichi_mpm.sysid.plot import plot_comparison

    settings = FitSettings(**fit)
    console = Console(highlight=False)
    family = family.lower()
    parameters = family_parameters(family)
    unknown = sorted(set(guess) - set(parameters))
    if unknown:
        raise click.BadParameter(
            f"{unknown} are not parameters of {family!r}; use some of {list(parameters)}",
            param_hint="'--guess'",
        )
    unknown = sorted(set(names) - set(parameters))
    if unknown:
        raise click.BadParameter(
            f"{unknown} are not parameters of {family!r}; use some of {list(parameters)}",
            param_hint="'--fit'",
        )
    try:
        material = material_family(family, **guess)
    except ValueError as error:  # a value out of its physical range
        raise click.BadParameter(str(error), param_hint="'--guess'") from None
    values = material.parameters()

    def fittable(name: str) -> bool:
        return TRANSFORMS[name].contains(values[name])

    if names:
        names = list(dict.fromkeys(names))
        for name in names:
            if not fittable(name):
                raise click.BadParameter(
                    f"{name}={values[name]:g} lies on the boundary of its range; fit it from "
                    f"an inside value, e.g. --guess {name}=0.01",
                    param_hint="'--guess'",
                )
    else:
        names = [name for name in parameters if fittable(name)]
        for name in parameters:
            if name not in names:
                console.print(
                    f"note: {name}={values[name]:g} is held fixed (on the boundary of its "
                    f"range); --fit {name} --guess {name}=VALUE fits it",
                    soft_wrap=True,
                )
    if out_dir.exists() and not out_dir.is_dir():
        raise click.BadParameter(f"'{out_dir}' is not a directory", param_hint="'--out-dir'")

    try:
        observation = load_observation(observed)
    except ObservationError as error:
        raise click.ClickException(str(error)) from error
    except ValueError as error:  # a scene field out of range (SceneError, MaterialError)
        raise click.ClickException(f"'{observed}': {error}") from error

    context = click.get_current_context()  # both end with the command
    heartbeat = context.with_resource(Heartbeat(active=not console.is_terminal))
    context.with_resource(FitPhases(heartbeat.state))
    heartbeat.state("starting Taichi")
    backend = start_taichi(console, arch, precision)
    velocity = None
    if settings.fit_velocity:
        velocity = tm.rigid_velocity_fit(observation.scene.positions, observation.scene.velocities)
    console.print(
        f"Fitting [bold]{', '.join(names)}[/] of {family} to {observation.positions.shape[1]} "
        f"particles x {len(observation.frame_steps)} frames ({observation.scene.steps} steps, "
        f"{backend}, {precision}, {settings.optimizer}, {restarts} run{'s' * (restarts > 1)})",
        soft_wrap=True,
    )
    heartbeat.said()

    iterations = settings.iterations
    total = restarts * iterations
    start = time.perf_counter()
    with Progress(
        TextColumn("[progress.description]{task.description}"),
        BarColumn(bar_width=20),
        MofNCompleteColumn(table_column=Column(no_wrap=True)),
        TimeElapsedColumn(table_column=Column(no_wrap=True)),
        TextColumn(
            "loss {task.fields[loss]}  {task.fields[values]}",
            table_column=Column(ratio=1, overflow="fold"),
        ),
        console=console,
    ) as progress:
        task = progress.add_task("fitting", total=total, loss="-", values="")

        def report(run: int, iteration: int, loss: float, current: dict[str, float]) -> None:
            shown = "  ".join(f"{key}={value:.4g}" for key, value in current.items())
            progress.update(
                task,
                completed=min(run * iterations + iteration, total),
                description=f"run {run + 1}/{restarts}",
                loss=f"{loss:.3e}",
                values=shown,
            )
            heartbeat.state(iteration_text(run, restarts, iteration, iterations, loss, current))

        try:
            result = identify(
                observation,
                material,
                names=names,
                restarts=restarts,
                settings=settings,
                initial_velocity=velocity,
                seed=seed,
                callback=report,
            )
        except (FitError, ValueError) as error:
            raise click.ClickException(f"the fit failed: {error}") from error
        progress.update(task, completed=total, description="done")
    seconds = time.perf_counter() - start
    console.print(result.summary(), markup=False, soft_wrap=True)
    heartbeat.said()
    heartbeat.state("simulating the fitted motion")

    best = result.best
    scene = observation.scene
    if best.initial_velocity is not None:
        scene = scene.with_velocities(
            tm.rigid_velocity(scene.positions, best.initial_velocity[:3], best.initial_velocity[3:])
        )
    fitted = tm.Simulator(scene, result.material).forward(observation.frame_steps)
    fitted = fitted[:, observation.particle_indices]

    record = {
        "observation": str(observed),
        "material": family,
        "fitted": names,
        "guess": values,
        "optimizer": settings.optimizer,
        "restarts": restarts,
        "learning_rate": settings.learning_rate,
        "precision": precision,
        "values": best.values,
        "parameters": result.material.parameters(),
        "loss": best.loss,
        "iterations": best.iterations,
        "converged": best.converged,
        "loss_curve": best.loss_curve,
        "history": best.history,
        "identifiable": result.identifiable,
        "warnings": result.warnings,
        "relative_std": result.relative_std,
        "initial_velocity": None
        if best.initial_velocity is None
        else {"linear": best.initial_velocity[:3], "angular": best.initial_velocity[3:]},
        "runs": [
            {
                "values": run.values,
                "loss": run.loss,
                "iterations": run.iterations,
                "converged": run.converged,
            }
            for run in result.runs
        ],
        "seconds": seconds,
    }
    best_run = next(i for i, run in enumerate(result.runs) if run is best)
    title = f"{family}: " + ", ".join(f"{k} = {v:.4g}" for k, v in best.values.items())
    heartbeat.state(f"writing fit.json and comparison.png to {out_dir}")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        json_path = out_dir / "fit.json"
        json_path.write_text(json.dumps(_json_ready(record), indent=2, allow_nan=False) + "\n")
        png_path = plot_comparison(
            observation.positions,
            fitted,
            observation.times,
            [run.loss_curve for run in result.runs],
            out_dir / "comparison.png",
            best_run=best_run,
            title=title,
        )
    except OSError as error:
        raise click.ClickException(f"could not write to '{out_dir}': {error}") from error
    heartbeat.stop()
    console.print(
        f"[green]done[/] in {seconds:.1f} s; wrote {json_path} and {png_path}", soft_wrap=True
    )
