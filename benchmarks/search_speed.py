"""Wall time of the README's main command, ``sga-agent search --task granular``, beside another
checkout's, in one run.

Each run starts the command in a fresh working folder (so no run store is reused) with the
code of one checkout on ``PYTHONPATH``: this one, and with ``--baseline`` another (a worktree
of an earlier commit), alternating for ``--rounds`` rounds. Taichi's kernel cache and the
ground truth under the home directory are shared and filled by an untimed first run of each
checkout (``--no-warm-up`` skips it when earlier runs filled them), so the rounds time the
search, not compilation. The table gives each run's seconds,
its best loss and the load average around it, then the ratio of the medians. Usage::

    python benchmarks/search_speed.py [--baseline ../before] [--rounds 1] [--task granular]
        [--seed 0] [--no-warm-up]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def run_search(tree: Path, task: str, seed: int) -> dict:
    """One ``sga-agent search`` with the code of checkout ``tree``, in a fresh folder."""
    path = os.pathsep.join([str(tree), os.environ.get("PYTHONPATH", "")])
    env = os.environ | {"PYTHONPATH": path}
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="search-speed-") as folder:
        started = time.perf_counter()
        out = subprocess.run([sys.executable, "-m", "sga_agent", "search", "--task", task,
                              "--seed", str(seed), "--json"], cwd=folder, env=env,
                             capture_output=True, text=True)  # fmt: skip
        seconds = time.perf_counter() - started
    if out.returncode != 0:
        sys.exit(f"the search from {tree} failed:\n{out.stderr[-3000:]}")
    return {"seconds": seconds, "best": _best(out.stdout), "load": load,
            "load_after": os.getloadavg()[0]}  # fmt: skip


def _best(stdout: str) -> dict:
    """The best solution of a ``--json`` summary (candidate, loss), empty if there is none."""
    for line in reversed(stdout.strip().splitlines()):
        try:
            summary = json.loads(line)
        except json.JSONDecodeError:
            continue
        best = summary.get("best") if isinstance(summary, dict) else None
        if isinstance(best, dict):
            return best
    return {}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", type=Path, help="another checkout of this project")
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--task", default="granular")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-warm-up", action="store_true",
                        help="no untimed first run (the caches are filled already)")  # fmt: skip
    args = parser.parse_args()
    trees = {"ours": ROOT} | ({"baseline": args.baseline.resolve()} if args.baseline else {})
    for tree in trees.values() if not args.no_warm_up else ():  # compiles, writes ground truth
        run_search(tree, args.task, args.seed)
    runs: dict[str, list[dict]] = {name: [] for name in trees}
    for _ in range(args.rounds):
        for name, tree in trees.items():
            runs[name].append(run_search(tree, args.task, args.seed))
    print(f"{os.cpu_count()} cores; sga-agent search --task {args.task} --seed {args.seed}")
    print(f"{'impl':<9} {'seconds':>8} {'best loss':>11} {'best candidate':>16} "
          f"{'load before/after':>18}")  # fmt: skip
    for name, results in runs.items():
        for run in results:
            loss = run["best"].get("loss", "-")
            loss = f"{loss:.4e}" if isinstance(loss, float) else str(loss)
            print(f"{name:<9} {run['seconds']:8.1f} {loss:>11} "
                  f"{run['best'].get('candidate', '-'):>16} "
                  f"{run['load']:8.2f} / {run['load_after']:.2f}")  # fmt: skip
    if "baseline" in runs:
        ratio = statistics.median(r["seconds"] for r in runs["baseline"]) / statistics.median(
            r["seconds"] for r in runs["ours"]
        )
        print(f"ours faster (medians): {ratio:.2f}x")


if __name__ == "__main__":
    main()
