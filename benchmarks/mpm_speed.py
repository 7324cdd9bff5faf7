"""Speed and memory of taichi_mpm: forward and forward+backward, two scenes, two materials.

Each configuration runs in a fresh subprocess so that its peak resident memory is its
own. Run from the repository root::

    python benchmarks/mpm_speed.py            # paper scene + 100k-particle scene
    python benchmarks/mpm_speed.py --quick    # paper scene only
    python benchmarks/mpm_speed.py --profile  # where the paper scene's time goes
    python benchmarks/mpm_speed.py --arch cuda --compare-arch cpu   # on a GPU, and agreement

Prints particle-steps per second, the wall time of the paper scene's 1000-step
forward+backward, peak memory, and the cold (empty offline cache) and warm start-up.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import taichi_mpm as tm

REPOSITORY = Path(__file__).resolve().parents[1]  # children import benchmarks.mpm_speed
PAPER_SCENE = {"scene": "paper", "steps": 1000}

MATERIALS = {
    "elastic": tm.Material(tm.NeoHookean(E=1e5, nu=0.3)),
    "plastic": tm.Material(tm.StVKHencky(E=1e5, nu=0.2), tm.VonMises(yield_stress=3e3)),
}

CHILD = r"""
import json, resource, sys, time
import numpy as np
import taichi_mpm as tm

config = json.loads(sys.argv[1])
t0 = time.perf_counter()
tm.init(arch=config["arch"], precision="float32", offline_cache_file_path=config["cache"])
if config["scene"] == "paper":
    scene = tm.paper_scene(steps=config["steps"])
else:
    positions, volume = tm.cube((0.5, 0.45, 0.5), 0.45, config["side"])
    velocities = tm.rigid_velocity(positions, (1.0, -0.5, -0.75), (1.0, 3.0, 2.0))
    scene = tm.Scene(positions, velocities, volume, grid_resolution=config["grid"],
                     dt=2e-4, steps=config["steps"])
from benchmarks.mpm_speed import MATERIALS
material = MATERIALS[config["material"]]
sim = tm.Simulator(scene, material)
frames = np.linspace(0, scene.steps, 11).astype(int)
positions = sim.forward(frames)
sim.backward(np.ones_like(positions))
startup = time.perf_counter() - t0  # includes compiling (or loading) every kernel
timings = {"forward": [], "forward_backward": []}
for _ in range(config["repeats"]):
    t = time.perf_counter()
    positions = sim.forward(frames)
    timings["forward"].append(time.perf_counter() - t)
    gradients = sim.backward(np.ones_like(positions))
    timings["forward_backward"].append(time.perf_counter() - t)
print(json.dumps({
    "final_positions": positions[-1].tolist(),
    "material_grads": gradients.material,
    "particles": scene.num_particles, "steps": scene.steps, "segment": sim.segment,
    "startup_s": startup,
    "forward_s": min(timings["forward"]),
    "forward_backward_s": min(timings["forward_backward"]),
    "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
}))
"""


PROFILE = r"""
import sys, time
import numpy as np
import taichi as ti
import taichi_mpm as tm
from benchmarks.mpm_speed import MATERIALS

tm.init(arch=sys.argv[1], precision="float32", kernel_profiler=True)
for name, material in MATERIALS.items():
    sim = tm.Simulator(tm.paper_scene(), material)
    frames = np.linspace(0, 1000, 11).astype(int)
    sim.backward(np.ones_like(sim.forward(frames)))  # compile
    ti.profiler.clear_kernel_profiler_info()
    t = time.perf_counter()
    sim.backward(np.ones_like(sim.forward(frames)))
    wall = time.perf_counter() - t
    records = ti.profiler.get_kernel_profiler_total_time()
    print(f"--- paper scene, {name}: forward+backward {wall:.2f} s, "
          f"of which in kernels {records:.2f} s, launches and Python {wall - records:.2f} s")
    ti.profiler.print_kernel_profiler_info("count")
"""


def run(config: dict) -> dict:
    out = subprocess.run(
        [sys.executable, "-c", CHILD, json.dumps(config)],
        check=True,
        capture_output=True,
        text=True,
        cwd=REPOSITORY,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def print_agreement(paper: list, other_arch: str, repeats: int) -> None:
    """Run the paper scene on ``other_arch`` and print how far its results are from ours."""
    with tempfile.TemporaryDirectory() as cache:
        for _, material, _, warm in paper:
            config = {**PAPER_SCENE, "material": material, "arch": other_arch, "cache": cache,
                      "repeats": repeats}  # fmt: skip
            other = run(config)
            here = np.asarray(warm["final_positions"])
            there = np.asarray(other["final_positions"])
            body = float(np.ptp(here, axis=0).max())
            grads = ", ".join(
                f"d/d{name} {value:.4g} vs {other['material_grads'][name]:.4g}"
                for name, value in warm["material_grads"].items()
            )
            print(
                f"paper scene, {material}, against {other_arch}: final positions differ by at most "
                f"{np.abs(here - there).max() / body:.2e} body sizes; {grads}; "
                f"fwd+bwd {other['forward_backward_s']:.2f} s there"
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="paper scene only")
    parser.add_argument("--arch", default="cpu", help="cpu, cuda, vulkan or gpu")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--profile", action="store_true", help="kernel profile of the paper scene")
    parser.add_argument("--compare-arch", metavar="ARCH",
                        help="also run the paper scene on ARCH and print how far the two agree")
    args = parser.parse_args()
    if args.profile:
        subprocess.run([sys.executable, "-c", PROFILE, args.arch], check=True, cwd=REPOSITORY)
        return

    scenes = [PAPER_SCENE]
    if not args.quick:
        scenes.append({"scene": "large", "side": 46, "grid": 64, "steps": 50})
    with tempfile.TemporaryDirectory() as cache:
        rows = []
        for scene in scenes:
            for material in ("elastic", "plastic"):
                config = {
                    **scene,
                    "material": material,
                    "arch": args.arch,
                    "cache": cache,
                    "repeats": args.repeats,
                }
                cold = run(config)  # first process on this cache: compiles
                warm = run(config)  # second: loads compiled kernels from the cache
                rows.append((scene["scene"], material, cold, warm))

    print(f"taichi_mpm speed, arch={args.arch}, float32, best of {args.repeats}")
    header = (
        f"{'scene':<7}{'material':<9}{'particles':>10}{'steps':>6}{'fwd Mp-steps/s':>16}"
        f"{'fwd+bwd Mp-steps/s':>20}{'fwd+bwd s':>11}{'peak MB':>9}{'cold s':>8}{'warm s':>8}"
    )
    print(header)
    for scene, material, cold, warm in rows:
        work = warm["particles"] * warm["steps"] / 1e6
        print(
            f"{scene:<7}{material:<9}{warm['particles']:>10}{warm['steps']:>6}"
            f"{work / warm['forward_s']:>16.2f}{work / warm['forward_backward_s']:>20.2f}"
            f"{warm['forward_backward_s']:>11.2f}{warm['peak_mb']:>9.0f}"
            f"{cold['startup_s']:>8.1f}{warm['startup_s']:>8.1f}"
        )
    paper = [r for r in rows if r[0] == "paper"]
    if args.compare_arch:
        print_agreement(paper, args.compare_arch, args.repeats)
    for _, material, _, warm in paper:
        print(
            f"paper scene, {material}: 1000-step forward+backward "
            f"{warm['forward_backward_s']:.2f} s, peak {warm['peak_mb']:.0f} MB"
        )


if __name__ == "__main__":
    t = time.perf_counter()
    main()
    print(f"benchmark wall time {time.perf_counter() - t:.0f} s")
