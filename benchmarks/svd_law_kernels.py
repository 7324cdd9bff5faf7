"""A law with an SVD of F, in torch against compiled with the SVD's factors as kernel inputs.

For each law (the example von Mises and Drucker-Prager laws 2x off, on ``plasticine`` and
``granular``, and a von Mises law of the genetic-programming grammar on ``plasticine``) and each
``law_kernels`` option (``none``: torch; ``svd-inputs``: the svd3 kernel, then the law's
compiled kernels reading U, S, Vh as inputs; with ``--sweeps`` also ``all``: the SVD written
out in the law's kernels as Jacobi sweeps), a fresh process runs ``evaluate`` as the fit
worker does (float32, one thread): one untimed epoch in torch (the simulator's kernels and
svd3's compile: a warm worker), then ``--epochs`` timed ones with the mode, whose law's
kernels compile first (those of a new law are never cached, and Taichi would reuse a second
compilation of the same law in one process). Runs alternate, mode by mode, law by law, for
``--rounds`` rounds; the table gives the medians over rounds of the compile seconds, the
median epoch, and the peak resident memory of the process as its parent reads it
(``wait4``), with the load average around the run.

``--per-step`` measures instead, in one process (float32, one thread), each law's compile time
both ways (``svd-inputs``, and ``all``'s sweeps) and the milliseconds of one step's law,
forward and reverse, on the 10,000 deformation gradients of an epoch's batch (10 scene
copies), the three ways and the SVD alone interleaved, median of ``--repeats``: what each of
an epoch's 100 batched steps pays for the law, without the rest of the epoch's noise. Usage::

    python benchmarks/svd_law_kernels.py [--epochs 3] [--rounds 2] [--steps 1000] [--sweeps]
    python benchmarks/svd_law_kernels.py --per-step [--repeats 50]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "scripts"))
from make_ground_truth import TWICE_OFF, truth_code  # noqa: E402

MODES = ("none", "svd-inputs")


def gp_von_mises() -> str:
    """Von Mises in the grammar (yield stress 6e4 Pa, 2x off), at weight 1/2."""
    from tasks.constitutive.gp.codegen import law_code
    from tasks.constitutive.gp.genome import Genome, Node, Param, Term

    eps = Node("eps")
    threshold = Node("const", (Param("log", math.log(6e4 / (2 * 1e6 / 2.4))),))
    mapped = Node("add", (Node("vol", (eps,)), Node("shrink", (Node("dev", (eps,)), threshold))))
    term = Term(Param("sigmoid", 0.0), Node("from_strain", (mapped,)))
    return law_code(Genome("plastic", (term,)))


def laws() -> dict[str, tuple[str, str]]:
    """Name: (task, code)."""
    return {"von_mises": ("plasticine", truth_code("plasticine", TWICE_OFF["plasticine"])),
            "drucker_prager": ("granular", truth_code("granular", TWICE_OFF["granular"])),
            "gp_von_mises": ("plasticine", gp_von_mises())}  # fmt: skip


def child(task: str, graph: Path, mode: str, epochs: int, steps: int) -> None:
    """Evaluate in this process and print the measurements as one JSON line."""
    from sga_agent.registry import load_task
    from sga_agent.task import EvaluationSettings
    from tasks.constitutive import law_kernel
    from tasks.constitutive.evaluation import ensure_runtime
    from tasks.constitutive.options import ConstitutiveOptions

    ensure_runtime("float32")
    compiles: list[tuple[float, bool]] = []
    kernel_law = law_kernel.kernel_law

    def timed(*args, **kwargs):
        started = time.perf_counter()
        compiled = kernel_law(*args, **kwargs)
        compiles.append((time.perf_counter() - started, compiled is not None))
        return compiled

    law_kernel.kernel_law = timed
    evaluator = load_task(task)
    data = json.loads(graph.read_text())
    warm = ConstitutiveOptions(steps=steps, law_kernels="none")
    evaluator.evaluate(data, EvaluationSettings(epochs=1, options=warm))
    options = ConstitutiveOptions(steps=steps, law_kernels=mode)
    result = evaluator.evaluate(data, EvaluationSettings(epochs=epochs, options=options))
    assert result.valid, result.reason
    print(json.dumps({"compile_s": compiles[-1][0] if compiles else 0.0,
                      "compiled": bool(compiles and compiles[-1][1]),
                      "epoch_s": statistics.median(result.extras["epoch_seconds"][:-1]),
                      "first_loss": result.curves["loss"][0]}))  # fmt: skip


def per_step(repeats: int) -> None:
    """Compile seconds and a step's law (forward and reverse) in milliseconds, by mode."""
    import torch

    import taichi_mpm as tm
    from bridges import linalg
    from sga_agent.registry import load_task
    from tasks.constitutive import law_kernel
    from tasks.constitutive.law_graph import build_law

    torch.set_num_threads(1)
    tm.init(arch="cpu", precision="float32", cpu_max_num_threads=1)
    noise = torch.randn(10_000, 3, 3, generator=torch.Generator().manual_seed(0))
    F = (torch.eye(3) + 0.05 * noise).requires_grad_(True)
    linalg.svd(F)[1].sum().backward()  # svd3 and its reverse compiled (a warm worker)
    print(f"{os.cpu_count()} cores; load average before {os.getloadavg()}; 10,000 matrices, "
          f"float32, 1 thread, median of {repeats}")  # fmt: skip
    print(f"{'law':<16} {'compile s: svd-inputs':>21} {'sweeps':>7}   "
          f"{'fwd+bwd ms: torch':>17} {'svd-inputs':>10} {'sweeps':>7} "
          f"{'SVD alone':>9}")  # fmt: skip
    for name, (task, code) in laws().items():
        law = build_law(load_task(task).capture(code)["law"], torch.float32)
        compiled, seconds = {}, {}
        for mode, flags in (("svd-inputs", {"factored": True}), ("sweeps", {"svd": True})):
            started = time.perf_counter()
            compiled[mode] = law_kernel.kernel_law(law, F.detach(), **flags)
            seconds[mode] = time.perf_counter() - started
            assert compiled[mode] is not None, (name, mode)
        times: dict[str, list[float]] = {"torch": [], **{mode: [] for mode in compiled}}
        times["svd"] = []  # the SVD the svd-inputs step takes, with its reverse
        with linalg.stable_linalg():
            for _ in range(repeats):
                for mode in times:
                    law.use_kernels(compiled.get(mode))
                    started = time.perf_counter()
                    outs = linalg.svd(F) if mode == "svd" else (law(F),)
                    sum(out.sum() for out in outs).backward()
                    times[mode].append(time.perf_counter() - started)
        ms = {mode: statistics.median(values) * 1e3 for mode, values in times.items()}
        print(f"{name:<16} {seconds['svd-inputs']:>21.2f} {seconds['sweeps']:>7.2f}   "
              f"{ms['torch']:>17.1f} {ms['svd-inputs']:>10.1f} {ms['sweeps']:>7.1f} "
              f"{ms['svd']:>9.1f}")  # fmt: skip
    print(f"load average after {os.getloadavg()}")


def run(task: str, graph: Path, mode: str, args: argparse.Namespace) -> dict:
    """One evaluation in a fresh one-thread process; its peak resident MB from ``wait4``."""
    command = [sys.executable, __file__, "--child", task, str(graph), mode,
               "--epochs", str(args.epochs), "--steps", str(args.steps)]  # fmt: skip
    threads = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "TI_CPU_MAX_NUM_THREADS": "1"}
    with tempfile.TemporaryFile("w+") as out:
        process = subprocess.Popen(command, stdout=out, stderr=subprocess.DEVNULL,
                                   env=os.environ | threads, cwd=ROOT)  # fmt: skip
        _, status, usage = os.wait4(process.pid, 0)
        process.returncode = os.waitstatus_to_exitcode(status)
        if process.returncode != 0:
            sys.exit(f"{task} {mode} failed with {process.returncode}")
        out.seek(0)
        row = json.loads(out.read().strip().splitlines()[-1])
    return row | {"peak_mb": usage.ru_maxrss / 1024}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--epochs", type=int, default=3)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--sweeps", action="store_true", help="add law_kernels=all")
    parser.add_argument("--per-step", action="store_true", help="a step's law alone")
    parser.add_argument("--repeats", type=int, default=50)
    parser.add_argument("--child", nargs=3, metavar=("TASK", "GRAPH", "MODE"))
    args = parser.parse_args()
    if args.per_step:
        per_step(args.repeats)
        return
    if args.child:
        task, graph, mode = args.child
        child(task, Path(graph), mode, args.epochs, args.steps)
        return
    from sga_agent.registry import load_task

    modes = (*MODES, "all") if args.sweeps else MODES
    rows: dict[tuple[str, str], list[dict]] = {}
    load = os.getloadavg()
    with tempfile.TemporaryDirectory() as folder:
        graphs = {}
        for name, (task, code) in laws().items():
            graphs[name] = Path(folder) / f"{name}.json"
            graphs[name].write_text(json.dumps(load_task(task).capture(code)))
        for _ in range(args.rounds):
            for name, (task, _code) in laws().items():
                for mode in modes:
                    rows.setdefault((name, mode), []).append(run(task, graphs[name], mode, args))
    print(f"{os.cpu_count()} cores; load average before {load}, after {os.getloadavg()}; "
          f"{args.epochs} epochs of {args.steps} steps, float32, 1 thread, "
          f"median of {args.rounds} rounds")  # fmt: skip
    print(f"{'law':<16} {'law_kernels':<12} {'compile s':>9} {'s/epoch':>8} {'vs torch':>8} "
          f"{'peak MB':>8} {'first loss':>11}")  # fmt: skip
    for (name, mode), runs in rows.items():
        torch_epoch = statistics.median(r["epoch_s"] for r in rows[name, "none"])
        epoch = statistics.median(r["epoch_s"] for r in runs)
        compile_s = statistics.median(r["compile_s"] for r in runs)
        compiled = "" if mode == "none" or all(r["compiled"] for r in runs) else " (torch)"
        print(f"{name:<16} {mode + compiled:<12} {compile_s:>9.2f} {epoch:>8.3f} "
              f"{torch_epoch / epoch:>7.2f}x {statistics.median(r['peak_mb'] for r in runs):>8.0f} "
              f"{runs[0]['first_loss']:>11.4g}")  # fmt: skip


if __name__ == "__main__":
    main()
