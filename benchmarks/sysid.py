"""System identification on the paper scene: speed and accuracy of Adam and L-BFGS.

For each built-in family (neo-Hookean E and nu, von Mises yield stress, Drucker-Prager
friction angle, fluid bulk modulus through E) a synthetic observation of the SGA paper's
scene (:func:`taichi_mpm.paper_scene`, float32) is fitted by
:func:`taichi_mpm.sysid.identify` from guesses 2.5x off (nu 0.3 -> 0.12, friction angle
30 -> 12 degrees). Run from the repository root::

    python benchmarks/sysid.py            # 1000 steps (about half an hour on 2 CPU cores)
    python benchmarks/sysid.py --quick    # 300 steps

Prints, per family and optimizer: the iterations run (until the stopping rule or the
cap), the first iteration within 1% of the truth, the simulations run (forward+backward,
line-search trials included, the uncertainty estimate excluded), the wall time of the fit
and of the whole identification (the fit plus the uncertainty estimate, 2 more
simulations per parameter), the final error of the worst parameter, and whether
:func:`~taichi_mpm.sysid.identify` reports every parameter identified.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import time

import numpy as np

import taichi_mpm as tm
from taichi_mpm.sysid import identify, observation_from_times
from taichi_mpm.sysid.families import DEFAULTS, material_family

# the module, not the function ``taichi_mpm.sysid.fit`` that shadows it
fit_module = importlib.import_module("taichi_mpm.sysid.fit")

#: family -> (fitted parameters, initial guesses); the truth is the family's defaults.
CASES: dict[str, tuple[tuple[str, ...], dict[str, float]]] = {
    "neohookean": (("E", "nu"), {"E": 2.5 * 5e4, "nu": 0.3 / 2.5}),
    "vonmises": (("yield_stress",), {"yield_stress": 2.5 * 2e3}),
    "sand": (("friction_angle",), {"friction_angle": 12.0}),
    "fluid": (("E",), {"E": 2.5 * 2e4}),
}
OPTIMIZERS = {"adam": {"learning_rate": 0.1}, "lbfgs": {"learning_rate": 0.5}}
#: An iteration is "within 1%" when every fitted parameter is.
CLOSE = 0.01


class _CountSimulations:
    """Counts the objective's evaluations (one forward + backward each) and their end times."""

    def __init__(self) -> None:
        self.ends: list[float] = []
        self._original = fit_module.Objective.__call__

    @property
    def count(self) -> int:
        return len(self.ends)

    def __enter__(self):
        counter, original = self, self._original

        def counted(objective, u):
            try:
                return original(objective, u)
            finally:
                counter.ends.append(time.perf_counter())

        fit_module.Objective.__call__ = counted
        return self

    def __exit__(self, *exc) -> None:
        fit_module.Objective.__call__ = self._original


def observe(family: str, steps: int, frames: int):
    scene = tm.paper_scene(steps=steps)
    frame_steps = np.unique(np.rint(np.linspace(steps / frames, steps, frames)).astype(int))
    positions = tm.Simulator(scene, material_family(family)).forward(frame_steps)
    return observation_from_times(scene, positions, frame_steps * scene.dt)


def run_case(family: str, optimizer: str, observation, iterations: int) -> dict:
    names, guess = CASES[family]
    truth = DEFAULTS[family]
    start = time.perf_counter()
    with _CountSimulations() as simulations:
        result = identify(
            observation,
            material_family(family, **guess),
            names=list(names),
            optimizer=optimizer,
            iterations=iterations,
            tolerance=1e-6,
            patience=10,
            **OPTIMIZERS[optimizer],
        )
    total = time.perf_counter() - start
    # identify ends with 2 simulations per parameter for the curvature (uncertainties)
    fit_simulations = max(simulations.count - 2 * len(names), 1)
    best = result.best
    errors = {name: abs(best.values[name] / truth[name] - 1.0) for name in names}
    history = np.array([[abs(v / truth[n] - 1.0) for v in best.history[n]] for n in names])
    close = np.nonzero(history.max(axis=0) < CLOSE)[0]
    return {
        "family": family,
        "fitted": ",".join(names),
        "optimizer": optimizer,
        "iterations": best.iterations,
        "converged": best.converged,
        "to_1pct": int(close[0]) + 1 if len(close) else None,
        "simulations": fit_simulations,
        "fit_s": simulations.ends[fit_simulations - 1] - start,
        "total_s": total,
        "error": max(errors.values()),
        "values": best.values,
        "loss": best.loss,
        "identifiable": result.identifiable,
        "warnings": result.warnings,
    }


def format_table(rows: list[dict]) -> str:
    header = (
        "| family | fitted | optimizer | iterations | within 1% at | simulations | "
        "fit (s) | total (s) | final rel. error | found | identified |"
    )
    lines = [header, "|" + "---|" * (header.count("|") - 1)]
    for row in rows:
        found = ", ".join(f"{k}={v:.4g}" for k, v in row["values"].items())
        lines.append(
            f"| {row['family']} | {row['fitted']} | {row['optimizer']} | "
            f"{row['iterations']}{'' if row['converged'] else '*'} | "
            f"{row['to_1pct'] if row['to_1pct'] is not None else 'never'} | "
            f"{row['simulations']} | {row['fit_s']:.1f} | {row['total_s']:.1f} | "
            f"{100 * row['error']:.2g}% | {found} | {'yes' if row['identifiable'] else 'no'} |"
        )
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=1000, help="scene steps (default 1000)")
    parser.add_argument("--quick", action="store_true", help="300 steps")
    parser.add_argument("--frames", type=int, default=10, help="observed frames (default 10)")
    parser.add_argument(
        "--iterations", type=int, default=60, help="most iterations per fit (default 60)"
    )
    parser.add_argument(
        "--families", nargs="+", choices=tuple(CASES), default=list(CASES), help="families"
    )
    parser.add_argument(
        "--optimizers",
        nargs="+",
        choices=tuple(OPTIMIZERS),
        default=list(OPTIMIZERS),
        help="optimizers",
    )
    parser.add_argument("--arch", default="cpu", choices=("cpu", "cuda", "vulkan", "gpu"))
    args = parser.parse_args(argv)
    steps = 300 if args.quick else args.steps

    info = tm.init(arch=args.arch, precision="float32")
    print(
        f"paper scene, {steps} steps, {args.frames} frames, float32 on {info.backend}; "
        f"at most {args.iterations} iterations, tolerance 1e-6 over 10 iterations",
        flush=True,
    )
    rows = []
    start = time.perf_counter()
    for family in args.families:
        observation = observe(family, steps, args.frames)
        for optimizer in args.optimizers:
            row = run_case(family, optimizer, observation, args.iterations)
            rows.append(row)
            print(
                f"  {family:<10} {optimizer:<5} {row['iterations']:>3} iterations, "
                f"{row['total_s']:6.1f} s, error {100 * row['error']:.2g}%",
                file=sys.stderr,
                flush=True,
            )
            for warning in row["warnings"]:
                print(f"    warning: {warning}", file=sys.stderr, flush=True)
    print()
    print(format_table(rows))
    print(
        "\n* stopped by the iteration cap or a failed line search, not by the tolerance rule."
        f"\ntotal {time.perf_counter() - start:.0f} s"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
