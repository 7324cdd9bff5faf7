"""Candidates a multi-fidelity search evaluates against a full-fidelity one in the same wall
time, in one run.

Each search is ``sga-agent search --task TASK --seed SEED --time-budget BUDGET`` with enough
iterations that the budget stops it, once with ``--fidelity multi`` and once with ``--fidelity
full`` (alternating, for ``--rounds`` rounds), each in a fresh folder; the kernel cache and the
ground truth under the home directory are shared (``--no-warm-up`` skips the untimed first
search that fills them). The table gives, per search, the candidates evaluated (screened or
fitted in full: every offspring with an evaluation or a screen), those fitted in full, the best
loss, the wall time and the load average before and after, then the ratio of the candidates
evaluated (median of multi over median of full). Usage::

    python benchmarks/fidelity.py [--budget 4m] [--rounds 1] [--task granular] [--seed 0]
        [--set KEY=VALUE ...] [--no-warm-up]

``--set`` passes a search option to both (``--set promote=0.2`` becomes ``--promote 0.2``).
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

FIDELITIES = ("multi", "full")


def run_search(task: str, seed: int, budget: str, fidelity: str, extra: list[str]) -> dict:
    """One search at ``fidelity`` in a fresh folder: its counts, best loss, seconds, load."""
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="fidelity-") as folder:
        command = [sys.executable, "-m", "sga_agent", "search", "--task", task, "--seed",
                   str(seed), "--time-budget", budget, "--iterations", "1000", "--fidelity",
                   fidelity, "--out-dir", folder, "--json", *extra]  # fmt: skip
        started = time.perf_counter()
        out = subprocess.run(command, capture_output=True, text=True)
        seconds = time.perf_counter() - started
        if out.returncode != 0:
            sys.exit(f"the {fidelity} search failed:\n{out.stderr[-3000:]}")
        (run,) = Path(folder).iterdir()
        counts = _counts(run / "events.jsonl")
    summary = json.loads(out.stdout.strip().splitlines()[-1])
    best = summary.get("best") or {}
    return {**counts, "best": best.get("loss"), "seconds": seconds, "load": load,
            "load_after": os.getloadavg()[0], "stopped": summary.get("stopped", "")}  # fmt: skip


def _counts(events: Path) -> dict[str, int]:
    """Offspring evaluated at any fidelity, and fitted in full, by the run's events."""
    screened, fitted = set(), set()
    for line in events.read_text(encoding="utf-8").splitlines():
        event = json.loads(line)
        if event.get("type") == "screened":
            screened.add(event["candidate"])
        elif event.get("type") == "evaluation" and event["candidate"] != "00-seed":
            fitted.add(event["candidate"])
    return {"candidates": len(screened | fitted), "full": len(fitted)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", default="4m", help="--time-budget of each search")
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--task", default="granular")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="a search option for both, e.g. promote=0.2")  # fmt: skip
    parser.add_argument("--no-warm-up", action="store_true",
                        help="no untimed first search (the caches are filled already)")  # fmt: skip
    args = parser.parse_args()
    extra = []
    for setting in args.set:
        key, _, value = setting.partition("=")
        extra += [f"--{key.replace('_', '-')}", value]
    if not args.no_warm_up:  # compiles, writes the ground truth
        run_search(args.task, args.seed, "30s", "multi", extra)
    runs: dict[str, list[dict]] = {fidelity: [] for fidelity in FIDELITIES}
    for _ in range(args.rounds):
        for fidelity in FIDELITIES:
            runs[fidelity].append(run_search(args.task, args.seed, args.budget, fidelity, extra))
    print(f"{os.cpu_count()} cores; sga-agent search --task {args.task} --seed {args.seed} "
          f"--time-budget {args.budget} {' '.join(extra)}")  # fmt: skip
    print(f"{'fidelity':<9} {'candidates':>10} {'full fits':>9} {'best loss':>11} "
          f"{'seconds':>8} {'load before/after':>18}")  # fmt: skip
    for fidelity, results in runs.items():
        for r in results:
            best = f"{r['best']:.5g}" if isinstance(r["best"], float) else str(r["best"])
            print(f"{fidelity:<9} {r['candidates']:>10} {r['full']:>9} {best:>11} "
                  f"{r['seconds']:>8.1f} {r['load']:>8.2f}/{r['load_after']:.2f}")  # fmt: skip
    median = {f: statistics.median(r["candidates"] for r in runs[f]) for f in FIDELITIES}
    ratio = median["multi"] / median["full"] if median["full"] else float("inf")
    print(f"candidates evaluated, multi / full: {ratio:.2f}x")


if __name__ == "__main__":
    main()
