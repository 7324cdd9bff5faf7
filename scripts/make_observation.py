"""Write a synthetic observation (.npz) of a built-in material for system identification.

Simulates a scene with hidden material parameters, keeps some frames (and optionally a
random subset of the particles), adds Gaussian noise, and writes the file that
``taichi-mpm sysid`` and :func:`taichi_mpm.sysid.load_observation` read::

    python scripts/make_observation.py obs.npz --material neohookean --param E=8e4
    python scripts/make_observation.py obs.npz --material sand --noise 0.01 --subset 0.5
    python scripts/make_observation.py obs.npz --material vonmises --scene paper --steps 300
    python scripts/make_observation.py big.npz --material neohookean --scene paper \
        --particles-per-side 30    # 27,000 particles on a 60^3 grid

The hidden material goes beside the file as ``OUT.truth.json`` (family and parameters), where
the ``observed`` task's report reads it; nothing shows it to a search.

Scenes: ``thrown`` is a 5^3-particle cube of side 0.2 thrown, spinning, into the floor of
a 16^3 grid (dt = 4e-4 s, 150 steps by default); ``gentle`` is the same cube tossed five times
slower (400 steps by default), so that a soft body's strains stay small; ``paper`` is the SGA
paper's scene (:func:`taichi_mpm.paper_scene`: 10^3 particles, 20^3 grid, dt = 5e-4 s, 1000
steps), refined by ``--particles-per-side n`` to n^3 particles on a (2n)^3 grid.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import click
import numpy as np

from taichi_mpm.frames import evenly_spaced
from taichi_mpm.sysid.families import (
    DEFAULTS,
    FAMILIES,
    FamilyError,
    material_family,
    parse_assignment,
)

SCENES = ("thrown", "gentle", "paper")
#: Default steps of each scene.
DEFAULT_STEPS = {"thrown": 150, "gentle": 400, "paper": 1000}
#: The thrown cube's velocity (m/s) and spin (rad/s); the gentle scene's are a fifth of them.
THROWN_VELOCITY, THROWN_SPIN = (0.8, -2.0, 0.3), (2.0, -1.0, 3.0)
GENTLE = 0.2


def thrown_scene(steps: int = 150, speed: float = 1.0):
    """The scene of tests/taichi_mpm/sysid/test_fit.py: a small cube thrown at the floor, its
    velocity and spin scaled by ``speed``."""
    import taichi_mpm as tm

    positions, volume = tm.cube((0.45, 0.3, 0.5), 0.2, 5)
    velocity = [speed * v for v in THROWN_VELOCITY]
    spin = [speed * w for w in THROWN_SPIN]
    velocities = tm.rigid_velocity(positions, velocity, spin)
    return tm.Scene(positions, velocities, volume, grid_resolution=16, dt=4e-4, steps=steps)


def make_scene(name: str, steps: int, particles_per_side: int | None = None):
    import taichi_mpm as tm

    if name == "paper":
        return tm.paper_scene(steps=steps, particles_per_side=particles_per_side or 10)
    return thrown_scene(steps, GENTLE if name == "gentle" else 1.0)


def observed_steps(steps: int, frames: int) -> np.ndarray:
    """``frames`` step indices evenly spaced over (0, steps], ending at ``steps``."""
    return evenly_spaced(steps / frames, steps, frames)


def _families_help() -> str:
    lines = [f"  {name:<11} {text}; defaults {DEFAULTS[name]}" for name, text in FAMILIES.items()]
    return "Material families:\n\n\b\n" + "\n".join(lines)


@click.command(
    help=__doc__.split("\n\n")[0]
    + "\n\nOUT is the observation file to write (.npz).\n\n"
    + _families_help(),
    context_settings={"help_option_names": ["-h", "--help"]},
)
@click.argument("out", type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--material",
    "family",
    required=True,
    type=click.Choice(tuple(FAMILIES)),
    help="Material family.",
)
@click.option(
    "--param",
    "assignments",
    multiple=True,
    metavar="NAME=VALUE",
    help="A hidden parameter value, e.g. --param E=5e4 --param nu=0.3 (repeatable); "
    "the others take the family's defaults.",
)
@click.option(
    "--noise",
    type=click.FloatRange(min=0),
    default=0.0,
    show_default=True,
    help="Standard deviation of the Gaussian position noise, as a fraction of the "
    "body size (0: exact positions).",
)
@click.option(
    "--frames",
    type=click.IntRange(min=2),
    default=15,
    show_default=True,
    help="Observed frames after t=0.",
)
@click.option(
    "--steps",
    type=click.IntRange(min=1),
    help="Time steps simulated [default: 150 for thrown, 1000 for paper].",
)
@click.option(
    "--subset",
    type=click.FloatRange(0, 1, min_open=True),
    default=1.0,
    show_default=True,
    help="Fraction of the particles observed, drawn at random.",
)
@click.option(
    "--seed", type=int, default=0, show_default=True, help="Seed of the noise and the subset."
)
@click.option(
    "--scene",
    "scene_name",
    type=click.Choice(SCENES),
    default="thrown",
    show_default=True,
    help="Scene.",
)
@click.option(
    "--particles-per-side",
    type=click.IntRange(min=2),
    help="Particles along each side of the paper scene's cube (its grid refined alike) "
    "[default: 10].",
)
@click.option(
    "--precision",
    type=click.Choice(("float32", "float64")),
    default="float64",
    show_default=True,
    help="Precision of the simulation.",
)
@click.option(
    "--arch",
    type=click.Choice(("cpu", "cuda", "vulkan", "gpu")),
    default="cpu",
    show_default=True,
    help="Taichi backend.",
)
def main(
    out: Path,
    family: str,
    assignments: tuple[str, ...],
    noise: float,
    frames: int,
    steps: int | None,
    subset: float,
    seed: int,
    scene_name: str,
    particles_per_side: int | None,
    precision: str,
    arch: str,
) -> None:
    """Simulate, sample frames and particles, add noise, write the observation."""
    params = {}
    for text in assignments:
        try:
            name, value = parse_assignment(text)
        except ValueError as error:
            raise click.BadParameter(str(error), param_hint="'--param'") from None
        params[name] = value
    try:
        material = material_family(family, **params)
    except (FamilyError, ValueError) as error:
        raise click.BadParameter(str(error), param_hint="'--param'") from None
    if not np.isfinite(noise):
        raise click.BadParameter(f"{noise} is not a finite number", param_hint="'--noise'")
    steps = DEFAULT_STEPS[scene_name] if steps is None else steps
    if frames > steps:
        raise click.BadParameter(f"{frames} exceeds --steps {steps}", param_hint="'--frames'")
    if particles_per_side is not None and scene_name != "paper":
        raise click.BadParameter(
            f"refines the paper scene only; add --scene paper (got --scene {scene_name})",
            param_hint="'--particles-per-side'",
        )
    if out.suffix != ".npz":
        raise click.BadParameter(f"{out} must end in .npz", param_hint="'OUT'")

    import taichi_mpm as tm
    from taichi_mpm.sysid import observation_from_times, save_observation

    scene = make_scene(scene_name, steps, particles_per_side)
    frame_steps = observed_steps(steps, frames)
    rng = np.random.default_rng(seed)

    start = time.perf_counter()
    tm.init(arch=arch, precision=precision)
    positions = tm.Simulator(scene, material).forward(frame_steps)
    seconds = time.perf_counter() - start
    if not np.isfinite(positions).all():
        raise click.ClickException(
            "the simulation diverged (NaN or inf positions); use a softer material, "
            "fewer steps or --precision float64"
        )

    count = scene.num_particles
    observed = max(1, int(round(subset * count)))
    indices = np.arange(count) if observed == count else np.sort(rng.choice(count, observed, False))
    positions = positions[:, indices]
    body_size = float(np.ptp(scene.positions, axis=0).max())
    if noise > 0:
        positions = positions + noise * body_size * rng.standard_normal(positions.shape)

    observation = observation_from_times(scene, positions, frame_steps * scene.dt, indices)
    out.parent.mkdir(parents=True, exist_ok=True)
    save_observation(out, observation)
    hidden = material.parameters()
    truth = out.with_suffix(".truth.json")
    truth.write_text(json.dumps({
        "family": family, "parameters": hidden, "noise": noise, "subset": subset,
        "frames": len(frame_steps), "seed": seed, "scene": scene_name, "steps": steps,
    }, indent=1) + "\n")  # fmt: skip

    click.echo(f"material family: {family} ({FAMILIES[family]})")
    click.echo("hidden parameters: " + ", ".join(f"{k}={v:g}" for k, v in hidden.items()))
    click.echo(
        f"scene: {scene_name}, {count} particles, grid {scene.grid_resolution}^3, "
        f"dt={scene.dt:g} s, {steps} steps ({precision}, simulated in {seconds:.1f} s)"
    )
    click.echo(
        f"wrote {out}: {len(frame_steps)} frames at t = {frame_steps[0] * scene.dt:g} .. "
        f"{frame_steps[-1] * scene.dt:g} s, {len(indices)} of {count} particles, "
        f"noise {noise:g} x body size {body_size:g} m (seed {seed})"
    )
    click.echo(f"wrote the hidden truth beside it, for reports only: {truth}")


if __name__ == "__main__":
    main()
