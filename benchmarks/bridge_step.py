"""Milliseconds of one bridge step, forward and reverse, on B copies of the paper scene.

A teacher-forced epoch runs its segments as one batch of scene copies (``bridges.step``), so
its Taichi time is that of this step on 10 copies (10,000 particles), 100 times. Each
configuration runs in a fresh process (Taichi's thread count is fixed when it starts): random
stresses, 20 timed steps after one untimed step, the mean wall time of a step's
``mpm_step`` + ``backward`` and, with ``--profile``, Taichi's kernel profile. Usage::

    python benchmarks/bridge_step.py [--copies 10 100] [--threads 1 2] [--profile] [--arch cuda]

With ``--arch cuda`` the tensors live on the GPU and Taichi runs there (its loops parallel).

To compare with an earlier commit, run the same command from a worktree of it.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

CHILD = r"""
import json, sys, time
import numpy as np, torch
import taichi as ti
import taichi_mpm as tm
config = json.loads(sys.argv[1])
torch.set_num_threads(config["threads"])
tm.init(arch=config["arch"], precision="float32", kernel_profiler=config["profile"])
device = "cuda" if config["arch"] == "cuda" else "cpu"
from bridges.step import Transfer, mpm_step
scene = tm.paper_scene(steps=100)
B, N = config["copies"], config["copies"] * scene.num_particles
parallel = {"auto": None, "serial": False, "parallel": True}[config["loops"]]
transfer = Transfer(scene, parallel=parallel, batch=B)
generator = torch.Generator().manual_seed(0)
inputs = [
    torch.as_tensor(np.tile(scene.positions, (B, 1)), dtype=torch.float32),
    torch.as_tensor(np.tile(scene.velocities, (B, 1)), dtype=torch.float32),
    torch.zeros(N, 3, 3),
    torch.eye(3).expand(N, 3, 3).contiguous(),
    1e3 * torch.randn(N, 3, 3, generator=generator),
]
leaves = [t.to(device).requires_grad_() for t in inputs]

def synchronize():
    ti.sync()
    if device == "cuda":
        torch.cuda.synchronize()

def step():
    outputs = mpm_step(*leaves, transfer)
    sum((o * o).sum() for o in outputs).backward()

step()
synchronize()
if config["profile"]:
    ti.profiler.clear_kernel_profiler_info()
started = time.perf_counter()
for _ in range(20):
    step()
synchronize()
print(json.dumps({"ms": (time.perf_counter() - started) / 20 * 1e3, "particles": N}))
if config["profile"]:
    ti.profiler.print_kernel_profiler_info()
"""


def run(config: dict) -> dict:
    """One configuration in a fresh process with ``threads`` Taichi and torch threads."""
    threads = str(config["threads"])
    env = os.environ | {"OMP_NUM_THREADS": threads, "TI_CPU_MAX_NUM_THREADS": threads}
    out = subprocess.run([sys.executable, "-c", CHILD, json.dumps(config)], check=True,
                         capture_output=True, text=True, env=env,
                         cwd=Path(__file__).resolve().parents[1])  # fmt: skip
    lines = out.stdout.strip().splitlines()
    row = json.loads(next(line for line in lines if line.startswith("{")))
    row["profile"] = "\n".join(line for line in lines if not line.startswith("{"))
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--copies", type=int, nargs="+", default=[10])
    parser.add_argument("--threads", type=int, nargs="+", default=[1])
    parser.add_argument("--loops", nargs="+", default=["auto"],
                        choices=["auto", "serial", "parallel"],
                        help="Taichi loops: the bridge's own choice, or forced")  # fmt: skip
    parser.add_argument("--profile", action="store_true", help="Taichi's kernel profile")
    parser.add_argument("--arch", default="cpu", choices=["cpu", "cuda"])
    args = parser.parse_args()
    print(f"{'copies':>6} {'particles':>9} {'threads':>7} {'loops':>8} {'ms per step':>11}")
    for copies in args.copies:
        for threads in args.threads:
            for loops in args.loops:
                config = {"copies": copies, "threads": threads, "loops": loops,
                          "profile": args.profile, "arch": args.arch}  # fmt: skip
                row = run(config)
                print(f"{copies:>6} {row['particles']:>9} {threads:>7} {loops:>8} "
                      f"{row['ms']:>11.1f}")  # fmt: skip
                if args.profile:
                    print(row["profile"])


if __name__ == "__main__":
    main()
