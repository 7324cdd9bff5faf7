"""``taichi-mpm demo``: simulate the paper's scene and save a picture."""

from __future__ import annotations

import time
from pathlib import Path

import click
import numpy as np
from rich.console import Console
from rich.text import Text

import taichi_mpm as tm
from taichi_mpm.cli import arch_option, main, precision_option, start_taichi
from taichi_mpm.cli.heartbeat import Heartbeat
from taichi_mpm.frames import evenly_spaced
from taichi_mpm.render import render_frames

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
    return evenly_spaced(0, steps, frames)


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


_DEMO_HELP = (
    "Simulate the SGA paper's scene and save a picture of it.\n\n"
    "A cube of 1000 particles (side 0.5, density 1e3) is thrown spinning into a box with "
    "slip walls, on a 20^3 grid with dt = 5e-4 s. The materials are:\n\n\b\n"
    + "\n".join(f"  {name:<11} {text}" for name, text in MATERIALS.items())
    + "\n\nWhile it works it shows what it does (the simulation, the picture): a live line on "
    "a terminal, else, from 5 s on, a plain line on stderr every 5 s."
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
@arch_option
@precision_option
def demo(material: str, steps: int, frames: int, out: Path, arch: str, precision: str) -> None:
    console = Console(highlight=False)
    out = _check_output(out)
    material = material.lower()
    scene = tm.paper_scene(steps=steps)
    step_indices = frame_steps(steps, frames)

    start = time.perf_counter()
    heartbeat = click.get_current_context().with_resource(Heartbeat(active=not console.is_terminal))
    heartbeat.state("starting Taichi")
    backend = start_taichi(console, arch, precision)
    simulating = (
        f"Simulating [bold]{material}[/]: {scene.num_particles} particles, {steps} steps "
        f"({backend}, {precision}); the first run compiles the kernels (about a minute)"
    )
    heartbeat.state(Text.from_markup(simulating).plain)
    with console.status(f"{simulating}...", spinner="dots"):
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
    heartbeat.state(f"Rendering {len(step_indices)} panels")
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
    heartbeat.stop()
    console.print(
        f"[green]done:[/] {material}, {steps} steps ({steps * scene.dt:g} s simulated) in "
        f"{total:.1f} s wall ({simulated:.1f} s simulating)",
        soft_wrap=True,
    )
    console.print(f"wrote {written}", soft_wrap=True)
