"""Write a synthetic observation (.npz) of a built-in material for system identification.

Simulates a scene with hidden material parameters, keeps some frames (and optionally a
random subset of the particles), adds Gaussian noise, and writes the file that
``taichi-mpm sysid`` and :func:`taichi_mpm.sysid.load_observation` read::

    python scripts/make_observation.py obs.npz --material neohookean --param E=8e4
    python scripts/make_observation.py obs.npz --material sand --noise 0.01 --subset 0.5
    python scripts/make_observation.py obs.npz --material vonmises --scene paper --steps 300

Scenes: ``thrown`` is a 5^3-particle cube of side 0.2 thrown, spinning, into the floor of
a 16^3 grid (dt = 4e-4 s, 150 steps by default); ``paper`` is the SGA paper's scene
(:func:`taichi_mpm.paper_scene`: 10^3 particles, 20^3 grid, dt = 5e-4 s, 1000 steps).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from taichi_mpm.sysid.families import (
    DEFAULTS,
    FAMILIES,
    FamilyError,
    material_family,
    parse_assignment,
)

SCENES = ("thrown", "paper")
#: Default steps of each scene.
DEFAULT_STEPS = {"thrown": 150, "paper": 1000}


def thrown_scene(steps: int = 150):
    """The scene of tests/taichi_mpm/sysid/test_fit.py: a small cube thrown at the floor."""
    import taichi_mpm as tm

    positions, volume = tm.cube((0.45, 0.3, 0.5), 0.2, 5)
    velocities = tm.rigid_velocity(positions, (0.8, -2.0, 0.3), (2.0, -1.0, 3.0))
    return tm.Scene(positions, velocities, volume, grid_resolution=16, dt=4e-4, steps=steps)


def make_scene(name: str, steps: int):
    import taichi_mpm as tm

    return thrown_scene(steps) if name == "thrown" else tm.paper_scene(steps=steps)


def observed_steps(steps: int, frames: int) -> np.ndarray:
    """``frames`` step indices evenly spaced over (0, steps], ending at ``steps``."""
    return np.unique(np.rint(np.linspace(steps / frames, steps, frames)).astype(np.int64))


def _positive_fraction(text: str) -> float:
    value = float(text)
    if not 0.0 < value <= 1.0:
        raise argparse.ArgumentTypeError(f"{text} must lie in (0, 1]")
    return value


def _non_negative(text: str) -> float:
    value = float(text)
    if not (np.isfinite(value) and value >= 0.0):
        raise argparse.ArgumentTypeError(f"{text} must be a finite number >= 0")
    return value


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text} must be >= 1")
    return value


def parse_args(argv=None) -> argparse.Namespace:
    families = "\n".join(
        f"  {name:<11} {text}; defaults {DEFAULTS[name]}" for name, text in FAMILIES.items()
    )
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        epilog="material families:\n" + families,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("out", type=Path, help="observation file to write (.npz)")
    parser.add_argument(
        "--material", required=True, choices=tuple(FAMILIES), help="material family"
    )
    parser.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a hidden parameter value, e.g. --param E=5e4 --param nu=0.3 (repeatable); "
        "the others take the family's defaults",
    )
    parser.add_argument(
        "--noise",
        type=_non_negative,
        default=0.0,
        help="standard deviation of the Gaussian position noise, as a fraction of the "
        "body size (default 0: exact positions)",
    )
    parser.add_argument(
        "--frames", type=_positive_int, default=15, help="observed frames after t=0 (default 15)"
    )
    parser.add_argument(
        "--steps",
        type=_positive_int,
        default=None,
        help="time steps simulated (default: 150 for thrown, 1000 for paper)",
    )
    parser.add_argument(
        "--subset",
        type=_positive_fraction,
        default=1.0,
        help="fraction of the particles observed, drawn at random (default 1: all)",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the noise and the subset")
    parser.add_argument("--scene", choices=SCENES, default="thrown", help="scene (default thrown)")
    parser.add_argument(
        "--precision",
        choices=("float32", "float64"),
        default="float64",
        help="precision of the simulation (default float64)",
    )
    parser.add_argument(
        "--arch", choices=("cpu", "cuda", "vulkan", "gpu"), default="cpu", help="Taichi backend"
    )
    args = parser.parse_args(argv)

    params = {}
    for text in args.param:
        try:
            name, value = parse_assignment(text)
        except ValueError as error:
            parser.error(f"--param: {error}")
        params[name] = value
    try:
        args.material_obj = material_family(args.material, **params)
    except (FamilyError, ValueError) as error:
        parser.error(f"--param: {error}")
    args.params = params
    if args.steps is None:
        args.steps = DEFAULT_STEPS[args.scene]
    if args.frames < 2:
        parser.error("--frames must be >= 2 (a fit needs at least two frames after t=0)")
    if args.frames > args.steps:
        parser.error(f"--frames {args.frames} exceeds --steps {args.steps}")
    if args.out.suffix != ".npz":
        parser.error(f"{args.out} must end in .npz")
    if args.out.is_dir():
        parser.error(f"{args.out} is a directory; give a file name")
    return args


def main(argv=None) -> int:
    args = parse_args(argv)

    import taichi_mpm as tm
    from taichi_mpm.sysid import observation_from_times, save_observation

    material = args.material_obj
    scene = make_scene(args.scene, args.steps)
    steps = observed_steps(args.steps, args.frames)
    rng = np.random.default_rng(args.seed)

    start = time.perf_counter()
    tm.init(arch=args.arch, precision=args.precision)
    positions = tm.Simulator(scene, material).forward(steps)
    seconds = time.perf_counter() - start
    if not np.isfinite(positions).all():
        print(
            "error: the simulation diverged (NaN or inf positions); use a softer material, "
            "fewer steps or --precision float64",
            file=sys.stderr,
        )
        return 1

    count = scene.num_particles
    observed = max(1, int(round(args.subset * count)))
    indices = np.arange(count) if observed == count else np.sort(rng.choice(count, observed, False))
    positions = positions[:, indices]
    body_size = float(np.ptp(scene.positions, axis=0).max())
    if args.noise > 0:
        positions = positions + args.noise * body_size * rng.standard_normal(positions.shape)

    observation = observation_from_times(scene, positions, steps * scene.dt, indices)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    save_observation(args.out, observation)

    hidden = material.parameters()
    print(f"material family: {args.material} ({FAMILIES[args.material]})")
    print("hidden parameters: " + ", ".join(f"{k}={v:g}" for k, v in hidden.items()))
    print(
        f"scene: {args.scene}, {count} particles, grid {scene.grid_resolution}^3, "
        f"dt={scene.dt:g} s, {args.steps} steps ({args.precision}, simulated in {seconds:.1f} s)"
    )
    print(
        f"wrote {args.out}: {len(steps)} frames at t = {steps[0] * scene.dt:g} .. "
        f"{steps[-1] * scene.dt:g} s, {len(indices)} of {count} particles, "
        f"noise {args.noise:g} x body size {body_size:g} m (seed {args.seed})"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
