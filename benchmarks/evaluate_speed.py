"""Seconds per epoch of a constitutive-law evaluation, ours beside the original's, in one run.

An epoch is the paper's inner-loop step on its scene (1000 particles, 20^3 grid, 1000 steps,
teacher forcing every 100): the forward rollout, the position loss, backward, gradient
clipping and one Adam step, with the ground-truth law started 2x off. Ours runs as
``evaluate`` runs it (the law captured into a graph, untimed, in a helper process, then fitted
in a fresh process, as the fit worker does);
the original (github.com/PingchuanMa/SGA, Warp + torch) runs through
``benchmarks/original_sga.py`` with 1 torch thread. The two alternate, task by task, for
``--rounds`` rounds, each run in a fresh process (so its peak memory is its own), and the
table gives the minimum, median and maximum epoch over all rounds, the ratio of the medians,
the peak resident memory, our runs' peak anonymous memory (their own heap, without the
libraries' code pages that every worker on a machine shares) and the load average around the
run. Without ``--original`` only our
own numbers are printed. ``--baseline`` adds another checkout of this project (a worktree of an
earlier commit) to the rotation, run the same way, with its ratio to ours. The original's driver
covers elastic and plasticine; our own runs cover every constitutive task. ``--profile`` prints
where our evaluations' time goes, by torch operation (each Taichi-backed step, SVD, stress or
product is one), and the time outside any operation. Every run also times each Taichi kernel
launch, so the table says where an epoch goes (the step's forward and reverse kernels, the laws'
kernels, the rest in torch and Python) and, beside the original, the speed-up that our kernels
alone would allow if everything else took no time. Usage::

    python benchmarks/evaluate_speed.py [--epochs 3] [--rounds 3] [--tasks elastic plasticine]
        [--original ~/SGA --original-python ~/orig-venv/bin/python] [--baseline ../before]
        [--profile] [--busy-core] [--option KEY=VALUE] [--variant LABEL:KEY=VALUE,...]

``--option`` sets a task option of our runs; ``--variant small:graph_memory_mb=100`` adds
this checkout with other options to the rotation, with its ratio to ours. ``--busy-core``
runs every configuration twice per round, alone and beside another process spinning on one
core (``python -c "while True: pass"``), and prints each one's slowdown.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "scripts"))
from make_ground_truth import TWICE_OFF, truth_code  # noqa: E402

from sga_agent.sandbox import resident_mb, threads_per_worker  # noqa: E402

ORIGINAL_DRIVER = Path(__file__).resolve().parent / "original_sga.py"
ORIGINAL_TASKS = ("elastic", "plasticine")  # what the original's driver runs
#: Environment variables that set a fit worker's threads.
THREAD_VARIABLES = ("OMP_", "MKL_", "OPENBLAS_", "TI_CPU_MAX_NUM_THREADS")


def law_code(task: str) -> str:
    """The task's ground-truth law with its parameters 2x off."""
    return truth_code(task, TWICE_OFF[task])


def capture(task: str, folder: Path) -> Path:
    """The 2x-off law's graph, captured in a helper process (its memory is not the fit's)."""
    path = folder / f"{task}.json"
    code = (
        "import json, sys; from sga_agent.registry import load_task; "
        "json.dump(load_task(sys.argv[1]).capture(sys.argv[2]), open(sys.argv[3], 'w'))"
    )
    subprocess.run([sys.executable, "-c", code, task, law_code(task), str(path)], check=True)
    return path


def run_one(task: str, epochs: int, profile: bool, graph: Path, raw: dict[str, str]) -> dict:
    """Evaluate in this process (called in a child) with the task options ``raw`` (texts);
    returns the measurements."""
    import torch

    from sga_agent.options import parse_options
    from sga_agent.registry import load_task
    from sga_agent.task import EvaluationSettings

    torch.set_num_threads(int(os.environ["OMP_NUM_THREADS"]))
    evaluator = load_task(task)
    options = parse_options(evaluator.options_type, raw, task)
    from tasks.constitutive.evaluation import ensure_runtime

    ensure_runtime("float32")
    baseline_mb = _resident_mb()  # torch, Taichi and the project imported, Taichi started
    own = AnonymousPeak()
    own.start()
    data = json.loads(graph.read_text())  # the law's graph: what the fit worker receives
    # compile every kernel, load the ground truth
    evaluator.evaluate(data, EvaluationSettings(epochs=1, options=options))
    settings = EvaluationSettings(epochs=epochs, options=options)
    clock = KernelClock()
    started = time.perf_counter()
    if profile:
        from torch.profiler import ProfilerActivity
        from torch.profiler import profile as torch_profile

        with torch_profile(activities=[ProfilerActivity.CPU]) as profiler:
            result = evaluator.evaluate(data, settings)
        seconds = time.perf_counter() - started
        print(where_the_time_goes(profiler, seconds, epochs), file=sys.stderr)
    else:
        result = evaluator.evaluate(data, settings)
        seconds = time.perf_counter() - started
    return {
        "task": task,
        "valid": result.valid,
        "seconds": seconds,
        "epochs": epochs,
        "first_loss": result.curves["loss"][0] if result.valid else math.nan,
        # the last entry is the forward-only scoring of the final parameters
        "epoch_seconds": result.extras["epoch_seconds"][:-1],
        "loss": result.loss,
        "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "own_peak_mb": own.stop(),
        "baseline_mb": baseline_mb,
        # Taichi's share of each epoch (the last entry is the final forward pass)
        "kernel_seconds": clock.by_call[:-1],
    }


class AnonymousPeak:
    """The peak of this process's anonymous memory (``Anonymous`` in /proc's smaps_rollup: its
    own heap, not the file-backed library pages that the processes on a machine share), polled
    every ``interval`` seconds by a daemon thread; None without /proc."""

    def __init__(self, interval: float = 0.1) -> None:
        self.interval = interval
        self.peak_mb: float | None = None
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._poll, daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> float | None:
        self._done.set()
        self._thread.join()
        return self.peak_mb

    def _poll(self) -> None:
        while True:
            current = anonymous_mb()
            if current is None:
                return
            self.peak_mb = max(self.peak_mb or 0.0, current)
            if self._done.wait(self.interval):
                return


def anonymous_mb() -> float | None:
    """This process's anonymous memory in MB, None where /proc cannot tell."""
    try:
        text = Path("/proc/self/smaps_rollup").read_text(encoding="ascii")
    except OSError:
        return None
    found = re.search(r"^Anonymous:\s+(\d+) kB", text, re.MULTILINE)
    return int(found.group(1)) / 1024 if found else None


class KernelClock:
    """Wall time of every Taichi kernel launch (launch cost included), by kernel, per call of
    the fit's ``trajectory_loss`` (one epoch each). Installed for the rest of the process: the
    benchmark's child times nothing else."""

    #: Kernel functions and the names the table gives them; any other kernel keeps its own.
    NAMES = {"step_forward": "step forward", "step_backward": "step reverse", "svd3": "SVD",
             "svd3_backward": "SVD reverse", "hencky_forward": "Hencky stress",
             "hencky_backward": "Hencky reverse", "product3": "3x3 products",
             "product3_backward": "3x3 products reverse", "compiled_law_forward": "compiled law",
             "compiled_law_reverse": "its reverse"}  # fmt: skip

    def __init__(self) -> None:
        from taichi_mpm import _compat
        from tasks.constitutive import inner

        self.totals: dict[str, float] = dict.fromkeys(self.NAMES.values(), 0.0)
        self.by_call: list[dict[str, float]] = []
        fitted_loss = inner.trajectory_loss

        def timed_launch(launch, kernel):
            started = time.perf_counter()
            try:
                return launch()
            finally:
                name = self.NAMES.get(kernel.func.__name__, kernel.func.__name__)
                self.totals[name] = self.totals.get(name, 0.0) + time.perf_counter() - started

        def counted_loss(*args, **kwargs):
            before = dict(self.totals)
            try:
                return fitted_loss(*args, **kwargs)
            finally:
                self.by_call.append({k: v - before.get(k, 0.0) for k, v in self.totals.items()})

        _compat.on_kernel_launch(timed_launch)
        inner.trajectory_loss = counted_loss


def where_the_time_goes(profiler, seconds: float, epochs: int, rows: int = 25) -> str:
    """The profiled evaluation's time by operation (self time: a Taichi-backed autograd
    Function's row holds its kernel launches), the rest being Python outside any operation."""
    averages = sorted(profiler.key_averages(), key=lambda a: a.self_cpu_time_total, reverse=True)
    total = sum(average.self_cpu_time_total for average in averages) / 1e6
    lines = [f"where {seconds:.2f} s go ({epochs} epochs and the final forward pass, profiled; "
             "the profiler adds its own overhead):",
             f"{'operation':<40} {'calls':>7} {'self s':>8} {'share':>6}"]  # fmt: skip
    for average in averages[:rows]:
        self_seconds = average.self_cpu_time_total / 1e6
        lines.append(f"{average.key[:40]:<40} {average.count:>7} {self_seconds:>8.3f} "
                     f"{self_seconds / seconds:>6.1%}")  # fmt: skip
    rest = sum(average.self_cpu_time_total for average in averages[rows:]) / 1e6
    lines.append(f"{'other operations':<40} {'':>7} {rest:>8.3f} {rest / seconds:>6.1%}")
    outside = seconds - total
    lines.append(f"{'outside operations (Python)':<40} {'':>7} {outside:>8.3f} "
                 f"{outside / seconds:>6.1%}")  # fmt: skip
    return "\n".join(lines)


def _largest(values) -> str:
    """The largest of the values that are not None, in whole MB, or "-" if there is none."""
    known = [value for value in values if value is not None]
    return f"{max(known):.0f}" if known else "-"


def _resident_mb() -> float:
    """Current resident memory (Linux /proc; the peak so far elsewhere)."""
    current = resident_mb()
    if current is not None:
        return current
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def run_ours(task: str, epochs: int, profile: bool, threads: int, graph: Path,
             options: dict[str, str], tree: Path = ROOT) -> dict:  # fmt: skip
    """Our evaluation of ``task`` in a fresh process with ``threads`` threads and the task
    options ``options`` (texts), by the code of checkout ``tree`` (this one by default)."""
    command = [sys.executable, str(tree / "benchmarks" / "evaluate_speed.py"), "--child", task,
               "--epochs", str(epochs), "--graph", str(graph)]  # fmt: skip
    for key, value in options.items():  # older checkouts know graph_memory_mb by its flag only
        command += (["--graph-memory-mb", value] if key == "graph_memory_mb"
                    else ["--option", f"{key}={value}"])  # fmt: skip
    if profile:
        command.append("--profile")
    path = os.pathsep.join([str(tree), os.environ.get("PYTHONPATH", "")])
    env = os.environ | fit_threads(tree, threads) | {"PYTHONPATH": path}
    out = subprocess.run(command, capture_output=True, text=True, check=True, env=env, cwd=tree)
    if profile:
        print(out.stderr)
    row = json.loads(out.stdout.strip().splitlines()[-1])
    return {"epoch_s": row["epoch_seconds"], "peak_mb": row["peak_mb"],
            "own_mb": row.get("own_peak_mb"), "row": row}  # fmt: skip


@functools.cache
def fit_threads(tree: Path, threads: int) -> dict[str, str]:
    """The thread settings that checkout ``tree``'s sandbox gives a fit worker with ``threads``
    threads (its own ``worker_environment``), so each commit runs as its evaluate would."""
    code = ("import json, sys; from sga_agent.sandbox import SandboxLimits, worker_environment; "
            "env = worker_environment(SandboxLimits(threads=int(sys.argv[1]))); "
            "print(json.dumps({k: v for k, v in env.items() if k.startswith(THREAD_VARIABLES)}))"
            ).replace("THREAD_VARIABLES", repr(THREAD_VARIABLES))  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code, str(threads)], capture_output=True,
                         text=True, check=True, cwd=tree,
                         env=os.environ | {"PYTHONPATH": str(tree)})  # fmt: skip
    return json.loads(out.stdout)


class BusyCore:
    """Another process spinning on one core for as long as the block lasts (--busy-core)."""

    def __init__(self, active: bool) -> None:
        self.active = active
        self._process: subprocess.Popen | None = None

    def __enter__(self) -> BusyCore:
        if self.active:
            self._process = subprocess.Popen([sys.executable, "-c", "while True: pass"])
            time.sleep(0.5)  # it is spinning before the timed process starts
        return self

    def __exit__(self, *exc) -> None:
        if self._process is not None:
            self._process.kill()
            self._process.wait()


def run_original(task: str, epochs: int, args: argparse.Namespace) -> dict:
    """The original's epochs of ``task`` in a fresh process (one untimed warm-up epoch)."""
    command = [str(args.original_python), str(ORIGINAL_DRIVER), "epoch", task, str(epochs),
               "--warmup", "1", "--data", str(args.original_data),
               "--work", str(args.original_data / "work")]  # fmt: skip
    env = os.environ | {"SGA_ORIGINAL": str(args.original), "OMP_NUM_THREADS": "1"}
    out = subprocess.run(command, capture_output=True, text=True, env=env)
    if out.returncode != 0:
        sys.exit(f"the original's {task} epoch failed:\n{out.stderr[-3000:]}")
    row = json.loads(out.stdout.strip().splitlines()[-1])
    return {"epoch_s": row["epoch_s"], "peak_mb": row["peak_mb"], "row": row}


def prepare_original(args: argparse.Namespace) -> None:
    """Write the original's ground truth of each task once (untimed)."""
    env = os.environ | {"SGA_ORIGINAL": str(args.original), "OMP_NUM_THREADS": "1"}
    for task in args.tasks:
        dataset = args.original_data / ("neohookean" if task == "elastic" else task)
        if (dataset / "state" / "ckpt.pt").exists():
            continue
        print(f"writing the original's {task} ground truth to {dataset} ...", flush=True)
        subprocess.run([str(args.original_python), str(ORIGINAL_DRIVER), "dataset", task,
                        str(args.original_data)], env=env, check=True)  # fmt: skip


def spread(values: list[float]) -> str:
    return f"{min(values):5.2f} / {statistics.median(values):5.2f} / {max(values):5.2f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--epochs", type=int, default=3, help="timed epochs per run")
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds per task")
    parser.add_argument("--tasks", nargs="+", default=list(ORIGINAL_TASKS),
                        choices=list(TWICE_OFF))  # fmt: skip
    parser.add_argument("--original", type=Path, help="a checkout of github.com/PingchuanMa/SGA")
    parser.add_argument("--original-python", type=Path, default=Path(sys.executable),
                        help="a Python with warp-lang 1.1.0, torch and numpy < 2")  # fmt: skip
    parser.add_argument("--original-data", type=Path,
                        default=Path.home() / ".cache" / "sga-benchmarks" / "original",
                        help="where the original's ground truth is written once")  # fmt: skip
    parser.add_argument("--baseline", type=Path,
                        help="another checkout of this project, timed beside ours")  # fmt: skip
    parser.add_argument("--profile", action="store_true",
                        help="where our evaluation's time goes, by torch operation")  # fmt: skip
    parser.add_argument("--threads", type=int, default=threads_per_worker(1),
                        help="our thread budget, spent as each checkout's sandbox spends it; "
                        "default: what sga-agent evaluate gives one evaluation, the machine's "
                        "cores")  # fmt: skip
    parser.add_argument("--graph-memory-mb", type=float,
                        help="our task option graph_memory_mb (default: the task's)")  # fmt: skip
    parser.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                        help="a task option for our runs (repeatable)")
    parser.add_argument("--variant", action="append", default=[], metavar="LABEL:KEY=VALUE,...",
                        help="also run ours with these task options, labelled LABEL, in the same "
                        "rotation (repeatable)")  # fmt: skip
    parser.add_argument("--busy-core", action="store_true",
                        help="run everything twice per round, alone and beside another process "
                        "spinning on one core")  # fmt: skip
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--graph", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        raw = our_options(args)
        print(json.dumps(run_one(args.child, args.epochs, args.profile, args.graph, raw)))
        return
    if args.original:
        if set(args.tasks) - set(ORIGINAL_TASKS):
            parser.error(f"--original covers only {', '.join(ORIGINAL_TASKS)}")
        prepare_original(args)
    ours = our_options(args)
    trees = {"ours": (ROOT, ours)} | variants(args.variant, ours)
    if args.baseline:
        trees["baseline"] = (args.baseline.resolve(), ours)
    folder = Path(tempfile.mkdtemp(prefix="evaluate-speed-"))
    graphs = {task: capture(task, folder) for task in args.tasks}
    for task in args.tasks:  # fills Taichi's kernel cache and the ground truth: no round compiles
        for tree, options in trees.values():
            run_ours(task, 1, False, args.threads, graphs[task], options, tree)
    conditions = ("alone", "busy") if args.busy_core else ("alone",)
    load_before = os.getloadavg()
    started = time.perf_counter()
    runs: dict[tuple[str, str, str], list[dict]] = {}
    for round_index in range(args.rounds):
        for task in args.tasks:
            for condition in conditions:
                for impl, (tree, options) in trees.items():
                    with BusyCore(condition == "busy"):
                        run = run_ours(task, args.epochs, args.profile, args.threads,
                                       graphs[task], options, tree)  # fmt: skip
                    runs.setdefault((impl, task, condition), []).append(run)
                if args.original:
                    with BusyCore(condition == "busy"):
                        run = run_original(task, args.epochs, args)
                    runs.setdefault(("original", task, condition), []).append(run)
            print(f"round {round_index + 1}/{args.rounds} {task}: done", file=sys.stderr)
    load_after = os.getloadavg()
    print(
        f"{os.cpu_count()} cores; load average (1/5/15 min) before "
        f"{'/'.join(f'{x:.2f}' for x in load_before)}, after "
        f"{'/'.join(f'{x:.2f}' for x in load_after)}; {time.perf_counter() - started:.0f} s; "
        f"{args.rounds} rounds x {args.epochs} epochs; ours with a budget of {args.threads} "
        "thread(s), the original on 1"
        + ("; 'busy': beside a process spinning on one core" if args.busy_core else "")
    )
    print(f"{'task':<11} {'impl':<9} {'load':<6} {'s/epoch min / median / max':>27} "
          f"{'peak MB':>8} {'own MB':>7} {'ours faster (medians)':>22}")  # fmt: skip
    labels = [name for name in trees if name not in ("ours", "baseline")]  # the --variant runs
    impls = ("original", "baseline", *labels, "ours")
    for name in labels:
        print(f"{name}: {trees[name][1]}")
    for task in args.tasks:
        medians = {}
        for condition in conditions:
            for impl in impls:
                if (impl, task, condition) not in runs:
                    continue
                epochs = [s for run in runs[impl, task, condition] for s in run["epoch_s"]]
                peak = max(run["peak_mb"] for run in runs[impl, task, condition])
                own = _largest(run.get("own_mb") for run in runs[impl, task, condition])
                medians[impl, condition] = statistics.median(epochs)
                print(f"{task:<11} {impl:<9} {condition:<6} {spread(epochs):>27} {peak:8.0f} "
                      f"{own:>7}")  # fmt: skip
            for impl in impls[:-1]:
                if (impl, condition) in medians:
                    ratio = medians[impl, condition] / medians["ours", condition]
                    print(f"{task:<11} {'':<9} {condition:<6} {'':>27} {'':>8} {'':>7} "
                          f"{ratio:>10.2f}x vs {impl}")  # fmt: skip
        if args.busy_core:
            for impl in impls:
                if (impl, "busy") in medians:
                    slowdown = medians[impl, "busy"] / medians[impl, "alone"]
                    print(f"{task:<11} {impl:<9} busy / alone: {slowdown:.2f}x")
        print(where_an_epoch_goes(task, runs["ours", task, "alone"],
                                  medians.get(("original", "alone"))))  # fmt: skip


def our_options(args: argparse.Namespace) -> dict[str, str]:
    """Our task options from ``--option`` and ``--graph-memory-mb`` (texts)."""
    options = dict(_key_value(text) for text in args.option)
    if args.graph_memory_mb is not None:
        options["graph_memory_mb"] = str(args.graph_memory_mb)
    return options


def variants(texts: list[str], ours: dict[str, str]) -> dict[str, tuple[Path, dict[str, str]]]:
    """``--variant LABEL:KEY=VALUE,...``: this checkout with these options on top of ours."""
    runs = {}
    for text in texts:
        label, _, pairs = text.partition(":")
        if not label or label in ("ours", "baseline", "original"):
            sys.exit(f"--variant {text!r}: label it, e.g. small:graph_memory_mb=100")
        runs[label] = (ROOT, ours | dict(_key_value(pair) for pair in pairs.split(",") if pair))
    return runs


def _key_value(text: str) -> tuple[str, str]:
    key, sep, value = text.partition("=")
    if not sep or not key:
        sys.exit(f"expected KEY=VALUE, got {text!r}")
    return key.strip(), value.strip()


def where_an_epoch_goes(task: str, runs: list[dict], original: float | None) -> str:
    """Our epoch split into Taichi's kernels (launches included) and the rest (torch and
    Python), medians over all epochs; with the original's median, the speed-up bound that the
    kernels set (everything else at zero cost)."""
    rows = [(s, k) for run in runs for s, k in zip(run["epoch_s"], run["row"]["kernel_seconds"],
                                                     strict=True)]  # fmt: skip
    names = [name for name in rows[0][1] if any(k.get(name, 0.0) > 0 for _, k in rows)]
    parts = {name: statistics.median(k.get(name, 0.0) for _, k in rows) for name in names}
    kernels = [sum(k.values()) for _, k in rows]
    parts["torch and Python"] = statistics.median(
        s - t for (s, _), t in zip(rows, kernels, strict=True)
    )
    lines = [f"{task:<11} ours, where an epoch goes (medians, s): " + ", ".join(
        f"{name} {seconds:.3f}" for name, seconds in parts.items()
    )]  # fmt: skip
    if original is not None:
        step = statistics.median(k["step forward"] + k["step reverse"] for _, k in rows)
        lines.append(f"{task:<11} ours at best, all else free: {original / step:.1f}x with the "
                     f"step kernels ({step:.3f} s), {original / statistics.median(kernels):.1f}x "
                     f"with all Taichi kernels ({statistics.median(kernels):.3f} s)")  # fmt: skip
    return "\n".join(lines)


if __name__ == "__main__":
    main()
