"""How the simulator and one evaluation of the ``observed`` task scale with the particle count.

The paper's scene refined to n^3 particles on a (2n)^3 grid (``taichi_mpm.paper_scene``; one
particle a cell as in the paper), for each ``--sides`` n, each measurement in a fresh process:

* ``mpm``: taichi_mpm alone, a neo-Hookean body, forward (11 frames kept) and forward+backward
  of ``--steps`` steps;
* ``neohookean``: one evaluation of ``observed`` with the elastic law searched, on a hidden
  observation of a neo-Hookean body (made as ``scripts/make_observation.py --scene paper``
  makes one: 15 frames, every particle, 0.2 % noise), the law in the loop a neo-Hookean one
  started off the truth (``examples/laws/neo_hookean.py``);
* ``vonmises``: the same with the plastic part searched, the elastic law given, on a von
  Mises body, the law in the loop von Mises (``examples/laws/von_mises.py``).

An evaluation fits ``--epochs`` epochs (each a forward pass and a checkpointed backward pass
of every step, the graph held within ``--graph-memory-mb``, the task's option). Printed per
row: seconds per particle-step (an epoch's, or the pass's), the resident memory the
measurement added at its peak (the peak is reset after the kernels compile and the data load,
so compiling does not count), the state's size (x, v, C, F of every particle) and, for an
evaluation, the checkpointed segment it ran and what its graph and checkpoints count (the
growth beyond the count is the allocator's, :data:`tasks.observed.evaluation.ALLOCATOR_SLACK`).
Writes ``scale.json`` and ``scale.png`` into
``--out`` (the plot with the rows of an earlier run's ``scale.json`` too, ``--plot-with``: a
larger size run with another budget, say). Usage::

    python benchmarks/scale.py [--sides 10 20 30 40] [--steps 1000] [--epochs 1]
        [--graph-memory-mb 1000] [--device cpu] [--out benchmarks/results/scale]
        [--plot-with OTHER/scale.json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[1]
PARTS = ("mpm", "neohookean", "vonmises")
#: The hidden materials of the observations and the laws started 2x off them.
TRUTH = {"neohookean": ("neohookean", {"E": 5e4, "nu": 0.3}),
         "vonmises": ("vonmises", {"E": 5e4, "nu": 0.3, "yield_stress": 1e3})}  # fmt: skip
NOISE, FRAMES = 0.002, 15

CHILD = r"""
import json, sys, time
import numpy as np
config = json.loads(sys.argv[1])
sys.path.insert(0, config["repository"])
from benchmarks.scale import measure
print(json.dumps(measure(config)))
"""


def memory_mb(key: str) -> float:
    """``VmRSS`` or ``VmHWM`` of this process, MB."""
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith(key + ":"):
                return int(line.split()[1]) / 1024
    raise RuntimeError(f"no {key} in /proc/self/status")


def reset_peak() -> float:
    """Start a new peak of resident memory (``VmHWM``); the resident memory now, MB."""
    with open("/proc/self/clear_refs", "w") as refs:
        refs.write("5")
    return memory_mb("VmRSS")


def measure(config: dict) -> dict:
    """One row, in this process (a child of :func:`main`)."""
    import taichi_mpm as tm

    tm.init(arch=config["device"], precision="float32")
    scene = tm.paper_scene(steps=config["steps"], particles_per_side=config["side"])
    row = {"part": config["part"], "particles": scene.num_particles, "steps": scene.steps,
           "state_mb": scene.num_particles * 24 * 4 / 2**20}  # fmt: skip
    if config["part"] == "mpm":
        return row | _measure_mpm(scene, config["repeats"])
    return row | _measure_evaluation(scene, config)


def _measure_mpm(scene, repeats: int) -> dict:
    import numpy as np

    import taichi_mpm as tm

    sim = tm.Simulator(scene, tm.Material(tm.NeoHookean(E=5e4, nu=0.3)))
    frames = np.linspace(0, scene.steps, 11).astype(int)
    sim.backward(np.ones_like(sim.forward(frames)))  # compile
    before = reset_peak()
    forward, both = [], []
    for _ in range(repeats):
        start = time.perf_counter()
        positions = sim.forward(frames)
        forward.append(time.perf_counter() - start)
        sim.backward(np.ones_like(positions))
        both.append(time.perf_counter() - start)
    work = scene.num_particles * scene.steps
    return {"forward_us": min(forward) / work * 1e6, "forward_backward_us": min(both) / work * 1e6,
            "added_mb": memory_mb("VmHWM") - before}  # fmt: skip


def _measure_evaluation(scene, config: dict) -> dict:
    import tempfile

    import numpy as np

    import taichi_mpm as tm
    from sga_agent.task import EvaluationSettings
    from taichi_mpm.frames import evenly_spaced
    from taichi_mpm.sysid import observation_from_times, save_observation
    from taichi_mpm.sysid.families import material_family
    from tasks.constitutive.law_capture import capture_law
    from tasks.observed.evaluation import evaluate, warm_up
    from tasks.observed.options import ObservedOptions

    family, parameters = TRUTH[config["part"]]
    material = material_family(family, **parameters)
    steps = evenly_spaced(scene.steps / FRAMES, scene.steps, FRAMES)
    positions = tm.Simulator(scene, material).forward(steps)
    size = float(np.ptp(scene.positions, axis=0).max())
    noise = NOISE * size * np.random.default_rng(0).standard_normal(positions.shape)
    observation = observation_from_times(scene, positions + noise, steps * scene.dt,
                                         np.arange(scene.num_particles))  # fmt: skip
    folder = Path(tempfile.mkdtemp())
    save_observation(folder / "observed.npz", observation)
    searched = "elastic" if family == "neohookean" else "plastic"
    known = {} if searched == "elastic" else {"E": parameters["E"], "nu": parameters["nu"]}
    options = ObservedOptions(str(folder / "observed.npz"), searched,
                              graph_memory_mb=config["graph_memory_mb"], **known)  # fmt: skip
    example = "neo_hookean.py" if searched == "elastic" else "von_mises.py"
    graph = capture_law((REPOSITORY / "examples" / "laws" / example).read_text())
    for _ in warm_up(options):
        pass
    before = reset_peak()
    found = evaluate({"law": graph}, EvaluationSettings(epochs=config["epochs"], options=options))
    added = memory_mb("VmHWM") - before
    if not found.valid:
        return {"refused": found.reason, "added_mb": added}
    epochs = found.extras["epoch_seconds"]
    return {"epoch_us": sum(epochs) / len(epochs) / (scene.num_particles * scene.steps) * 1e6,
            "added_mb": added, "loss": found.loss, **_segment(options, graph),
            "budget_mb": config["graph_memory_mb"]}  # fmt: skip


def _segment(options, graph) -> dict:
    """The checkpointed segment the evaluation ran (planned again, as it plans it) and what
    its graph and checkpoints count, MB (without the allocator's slack)."""
    from bridges.rollout import checkpoint_segment
    from bridges.step import torch_dtype
    from tasks.constitutive.law_graph import build_law
    from tasks.observed.data import ObservedData
    from tasks.observed.evaluation import gradient_segment, rollout_for

    data = ObservedData.load(options.observation)
    law = build_law(graph, torch_dtype())
    rollout = rollout_for(law, data.scene, options, torch_dtype())
    segment = gradient_segment(rollout, options)
    counted = checkpoint_segment(rollout, data.scene.steps, 2**62, segment)[1]
    return {"segment": segment, "counted_mb": counted / 2**20}


def run(config: dict) -> dict:
    env = os.environ | {"OMP_NUM_THREADS": "1", "LITELLM_LOCAL_MODEL_COST_MAP": "True"}
    out = subprocess.run([sys.executable, "-c", CHILD, json.dumps(config)], check=True,
                         capture_output=True, text=True, cwd=REPOSITORY, env=env)  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


def plot(path: Path, rows: list[dict]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (speed, memory) = plt.subplots(1, 2, figsize=(10, 4))
    series = {"mpm forward": ("mpm", "forward_us"), "mpm forward+backward":
              ("mpm", "forward_backward_us"), "observed, neo-Hookean": ("neohookean", "epoch_us"),
              "observed, von Mises": ("vonmises", "epoch_us")}  # fmt: skip
    for label, (part, key) in series.items():
        points = [(r["particles"], r[key]) for r in rows if r["part"] == part and key in r]
        if points:
            speed.plot(*zip(*points, strict=True), marker="o", label=label)
    for part in PARTS:
        points = [(r["particles"], r["added_mb"]) for r in rows if r["part"] == part]
        if points:
            memory.plot(*zip(*points, strict=True), marker="o", label=part)
    states = sorted({(r["particles"], r["state_mb"]) for r in rows})
    memory.plot(*zip(*states, strict=True), linestyle=":", color="gray", label="state")
    speed.set(xscale="log", xlabel="particles", ylabel="µs per particle-step",
              title="time per particle-step")  # fmt: skip
    memory.set(xscale="log", yscale="log", xlabel="particles", ylabel="MB added at peak",
               title="memory")  # fmt: skip
    speed.legend(fontsize=8)
    memory.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sides", type=int, nargs="+", default=[10, 20, 30, 40])
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--epochs", type=int, default=1)
    parser.add_argument("--repeats", type=int, default=2, help="of the simulator's passes")
    parser.add_argument("--graph-memory-mb", type=float, default=1000.0)
    parser.add_argument("--device", choices=("cpu", "cuda"), default="cpu",
                        help="Taichi's arch (torch laws stay on the CPU)")
    parser.add_argument("--parts", nargs="+", choices=PARTS, default=list(PARTS))
    parser.add_argument("--out", type=Path, default=REPOSITORY / "benchmarks/results/scale")
    parser.add_argument("--plot-with", type=Path, help="an earlier run's scale.json")
    args = parser.parse_args()
    started = time.perf_counter()
    load = os.getloadavg()[0]
    rows = []
    for side in args.sides:
        for part in args.parts:
            config = {"repository": str(REPOSITORY), "part": part, "side": side,
                      "steps": args.steps, "epochs": args.epochs, "repeats": args.repeats,
                      "graph_memory_mb": args.graph_memory_mb, "device": args.device}  # fmt: skip
            row = run(config)
            rows.append(row)
            print(describe(row), flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "scale.json").write_text(json.dumps(rows, indent=1) + "\n")
    earlier = json.loads(args.plot_with.read_text()) if args.plot_with else []
    plot(args.out / "scale.png", sorted(earlier + rows, key=lambda row: row["particles"]))
    print(f"load {load:.2f} before, {os.getloadavg()[0]:.2f} after; "
          f"{time.perf_counter() - started:.0f} s; wrote {args.out / 'scale.json'} and "
          f"{args.out / 'scale.png'}")  # fmt: skip


def describe(row: dict) -> str:
    head = f"{row['part']:<11}{row['particles']:>7} particles {row['steps']} steps: "
    tail = f"; added {row['added_mb']:.0f} MB at peak (state {row['state_mb']:.1f} MB)"
    if row["part"] == "mpm":
        return head + (f"forward {row['forward_us']:.3f} µs, forward+backward "
                       f"{row['forward_backward_us']:.3f} µs a particle-step") + tail  # fmt: skip
    if "refused" in row:
        return head + f"refused: {row['refused']}" + tail
    counted = (f" (graph and checkpoints counted {row['counted_mb']:.0f} MB: added "
               f"{row['added_mb'] / row['counted_mb']:.2f}x that)" if "counted_mb" in row else "")
    return head + (f"an epoch {row['epoch_us']:.3f} µs a particle-step, segments of "
                   f"{row['segment']} steps{counted} within {row['budget_mb']:g} MB, loss "
                   f"{row['loss']:.3g}") + tail  # fmt: skip


if __name__ == "__main__":
    main()
