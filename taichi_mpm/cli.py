"""Command line interface: ``taichi-mpm`` (or ``python -m taichi_mpm``)."""

from __future__ import annotations

import json
import time
from pathlib import Path

import click
import numpy as np
from rich.console import Console

import taichi_mpm as tm
from taichi_mpm.render import render_frames
from taichi_mpm.sysid.families import (
    FAMILIES,
    family_parameters,
    material_family,
    parse_assignment,
)

ARCHS = ("cpu", "cuda", "vulkan", "gpu")
PRECISIONS = ("float32", "float64")
#: Most panels a demo picture may have (beyond this the panels become too small to read).
MAX_FRAMES = 12

#: Demo materials and what they do in the paper scene.
MATERIALS: dict[str, str] = {
    "elastic": "neo-Hookean jelly (E=2e5 Pa, nu=0.3): bounces back",
    "plasticine": "StVK-Hencky (E=1e5, nu=0.2) + von Mises (yield 2e3 Pa): squashes and stays",
    "sand": "StVK-Hencky (E=1e5, nu=0.2) + Drucker-Prager (25 deg): slumps into a pile",
    "fluid": "StVK-Hencky (E=1e5, nu=0.2) + weakly compressible fluid: splashes and spreads",
    "imaginary": "StVK-Hencky + 0.5 von Mises + 0.3 Drucker-Prager + 0.2 fluid (the paper's)",
}


def make_material(name: str) -> tm.Material:
    """The demo material ``name`` (a key of :data:`MATERIALS`).

    All are stable in the paper scene (dx = 0.05, dt = 5e-4 s, density 1e3): the stiffest,
    the neo-Hookean E = 2e5, nu = 0.3, has a P-wave speed of 16 m/s, a CFL number of 0.16.
    """
    hencky = tm.StVKHencky(E=1e5, nu=0.2)
    von_mises = tm.VonMises(yield_stress=2e3)
    sand = tm.DruckerPrager(friction_angle=25.0)
    if name == "elastic":
        return tm.Material(tm.NeoHookean(E=2e5, nu=0.3))
    if name == "plasticine":
        return tm.Material(hencky, von_mises)
    if name == "sand":
        return tm.Material(hencky, sand)
    if name == "fluid":
        return tm.Material(hencky, tm.WeaklyCompressibleFluid())
    if name == "imaginary":
        mixture = ((0.5, von_mises), (0.3, sand), (0.2, tm.WeaklyCompressibleFluid()))
        return tm.Material(hencky, tm.PlasticMixture(mixture))
    raise ValueError(f"unknown material {name!r}; use one of {sorted(MATERIALS)}")


def frame_steps(steps: int, frames: int) -> np.ndarray:
    """``frames`` step indices evenly spaced over [0, steps]; a single frame shows the end."""
    if frames == 1:
        return np.array([steps])
    return np.unique(np.linspace(0, steps, frames).round().astype(np.int64))


def _check_output(out: Path) -> Path:
    """Reject output paths that cannot be written as a PNG before anything runs."""
    if out.suffix.lower() != ".png":
        raise click.BadParameter(f"'{out}' must end in .png", param_hint="'--out'")
    if out.is_dir():
        raise click.BadParameter(f"'{out}' is a directory; give a file name", param_hint="'--out'")
    for parent in out.parents:
        if parent.exists():
            if not parent.is_dir():
                raise click.BadParameter(
                    f"'{parent}' is not a directory, so '{out}' cannot be created",
                    param_hint="'--out'",
                )
            break
    return out


def _start_taichi(console: Console, arch: str, precision: str) -> str:
    """Initialise Taichi; warn when it falls back to another backend; returns the backend."""
    try:
        info = tm.init(arch=arch, precision=precision)
    except Exception as error:  # Taichi raises several types for an unavailable backend
        raise click.ClickException(f"could not start Taichi on arch={arch}: {error}") from error
    if arch in ("cuda", "vulkan") and info.backend != arch:
        console.print(f"[yellow]warning:[/] no {arch} backend here; Taichi runs on {info.backend}")
    return info.backend


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
def main() -> None:
    """taichi-mpm: a differentiable 3D MLS-MPM simulator in Taichi.

    Run `taichi-mpm demo --help` to simulate a spinning cube of one of several materials
    and save a picture of its motion.
    """


_DEMO_HELP = (
    "Simulate the SGA paper's scene and save a picture of it.\n\n"
    "A cube of 1000 particles (side 0.5, density 1e3) is thrown spinning into a box with "
    "slip walls, on a 20^3 grid with dt = 5e-4 s. The materials are:\n\n\b\n"
    + "\n".join(f"  {name:<11} {text}" for name, text in MATERIALS.items())
)


@main.command(help=_DEMO_HELP)
@click.option(
    "--material",
    type=click.Choice(tuple(MATERIALS), case_sensitive=False),
    default="plasticine",
    show_default=True,
    help="Constitutive law of the cube.",
)
@click.option(
    "--steps",
    type=click.IntRange(min=1),
    default=1000,
    show_default=True,
    help="Time steps of 5e-4 s to simulate.",
)
@click.option(
    "--frames",
    type=click.IntRange(1, MAX_FRAMES),
    default=4,
    show_default=True,
    help="Panels in the picture, at evenly spaced times from start to end.",
)
@click.option(
    "--out",
    type=click.Path(dir_okay=False, path_type=Path),
    default=Path("demo.png"),
    show_default=True,
    help="PNG file to write (missing parent folders are created).",
)
@click.option(
    "--arch", type=click.Choice(ARCHS), default="cpu", show_default=True, help="Taichi backend."
)
@click.option(
    "--precision",
    type=click.Choice(PRECISIONS),
    default="float32",
    show_default=True,
    help="Floating-point type of the simulation.",
)
def demo(material: str, steps: int, frames: int, out: Path, arch: str, precision: str) -> None:
    console = Console(highlight=False)
    out = _check_output(out)
    material = material.lower()
    scene = tm.paper_scene(steps=steps)
    step_indices = frame_steps(steps, frames)

    start = time.perf_counter()
    backend = _start_taichi(console, arch, precision)
    with console.status(
        f"Simulating [bold]{material}[/]: {scene.num_particles} particles, {steps} steps "
        f"({backend}, {precision})...",
        spinner="dots",
    ):
        positions = tm.Simulator(scene, make_material(material)).forward(step_indices)
    simulated = time.perf_counter() - start
    if not np.isfinite(positions).all():
        raise click.ClickException(
            f"the {material} simulation diverged (NaN or inf positions); "
            "try fewer steps or --precision float64"
        )
    low, high = float(positions.min()), float(positions.max())
    if low < 0.0 or high > scene.domain_size:
        console.print(
            f"[yellow]warning:[/] particles left the domain: coordinates in [{low:.3f}, {high:.3f}]"
        )

    titles = [f"t = {s * scene.dt:.3g} s" for s in step_indices]
    with console.status(f"Rendering {len(step_indices)} panels...", spinner="dots"):
        try:
            written = render_frames(
                positions,
                out,
                titles=titles,
                domain_size=scene.domain_size,
                floor=scene.walls.thickness * scene.dx,
            )
        except OSError as error:
            raise click.ClickException(f"could not write '{out}': {error}") from error
    total = time.perf_counter() - start
    console.print(
        f"[green]done:[/] {material}, {steps} steps ({steps * scene.dt:g} s simulated) in "
        f"{total:.1f} s wall ({simulated:.1f} s simulating)",
        soft_wrap=True,
    )
    console.print(f"wrote {written}", soft_wrap=True)


@main.command()
@click.option(
    "--arch", type=click.Choice(ARCHS), default="cpu", show_default=True, help="Taichi backend."
)
@click.option(
    "--precision",
    type=click.Choice((*PRECISIONS, "both")),
    default="both",
    show_default=True,
    help="Precision(s) to compile for.",
)
def warmup(arch: str, precision: str) -> None:
    """Compile every kernel once, filling Taichi's offline cache.

    Later processes then start in seconds instead of minutes.
    """
    console = Console(highlight=False)
    for chosen in PRECISIONS if precision == "both" else (precision,):
        backend = _start_taichi(console, arch, chosen)
        with console.status(f"Compiling kernels ({backend}, {chosen})...", spinner="dots"):
            seconds = tm.warm_up()
        console.print(f"[green]compiled[/] {backend} {chosen} kernels in {seconds:.1f} s")


# ----------------------------------------------------------------------------- sysid

_SYSID_HELP = (
    "Fit material parameters to an observed motion (system identification).\n\n"
    "OBSERVED is an observation .npz (see taichi_mpm.sysid.observation; "
    "scripts/make_observation.py writes synthetic ones). The material families are:\n\n\b\n"
    + "\n".join(f"  {name:<11} {text}" for name, text in FAMILIES.items())
    + "\n\nWrites fit.json (values, loss curve, history, warnings, relative standard "
    "deviations) and comparison.png (observed vs fitted particles, loss curve) to --out-dir."
)


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


def _rigid_motion(positions: np.ndarray, velocities: np.ndarray):
    """Least-squares (linear, angular) with velocities ~ linear + angular x (x - centroid)."""
    arm = positions - positions.mean(axis=0)
    linear = velocities.mean(axis=0)
    # angular x r = -r x angular = -[r]_x angular
    skew = np.zeros((len(arm), 3, 3))
    skew[:, 0, 1], skew[:, 0, 2] = arm[:, 2], -arm[:, 1]
    skew[:, 1, 0], skew[:, 1, 2] = -arm[:, 2], arm[:, 0]
    skew[:, 2, 0], skew[:, 2, 1] = arm[:, 1], -arm[:, 0]
    angular = np.linalg.lstsq(skew.reshape(-1, 3), (velocities - linear).ravel(), rcond=None)[0]
    return linear, angular


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
@click.argument("observed", type=click.Path(dir_okay=False, path_type=Path))
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
@click.option(
    "--arch", type=click.Choice(ARCHS), default="cpu", show_default=True, help="Taichi backend."
)
@click.option(
    "--precision",
    type=click.Choice(PRECISIONS),
    default="float32",
    show_default=True,
    help="Floating-point type of the simulation.",
)
def sysid(
    observed: Path,
    family: str,
    names: tuple[str, ...],
    guess: dict[str, float],
    optimizer: str,
    restarts: int,
    iterations: int,
    learning_rate: float,
    fit_velocity: bool,
    seed: int,
    out_dir: Path,
    arch: str,
    precision: str,
) -> None:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
    from rich.table import Column

    from taichi_mpm.sysid import FitError, ObservationError, identify, load_observation
    from taichi_mpm.sysid.parameters import TRANSFORMS
    from taichi_mpm.sysid.plot import plot_comparison

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
        transform = TRANSFORMS[name]
        return transform.low < values[name] < transform.high

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

    backend = _start_taichi(console, arch, precision)
    velocity = None
    if fit_velocity:
        velocity = _rigid_motion(observation.scene.positions, observation.scene.velocities)
    console.print(
        f"Fitting [bold]{', '.join(names)}[/] of {family} to {observation.positions.shape[1]} "
        f"particles x {len(observation.frame_steps)} frames ({observation.scene.steps} steps, "
        f"{backend}, {precision}, {optimizer}, {restarts} run{'s' * (restarts > 1)})",
        soft_wrap=True,
    )

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

        try:
            result = identify(
                observation,
                material,
                names=names,
                optimizer=optimizer,
                restarts=restarts,
                iterations=iterations,
                learning_rate=learning_rate,
                fit_velocity=fit_velocity,
                initial_velocity=velocity,
                seed=seed,
                callback=report,
            )
        except (FitError, ValueError) as error:
            raise click.ClickException(f"the fit failed: {error}") from error
        progress.update(task, completed=total, description="done")
    seconds = time.perf_counter() - start
    console.print(result.summary(), markup=False, soft_wrap=True)

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
        "optimizer": optimizer,
        "restarts": restarts,
        "learning_rate": learning_rate,
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
    console.print(
        f"[green]done[/] in {seconds:.1f} s; wrote {json_path} and {png_path}", soft_wrap=True
    )
