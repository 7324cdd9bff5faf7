"""One ``sga-agent evaluate`` of this checkout against another checkout's, interleaved.

Times the whole command (a fresh process: start-up, the sandbox, the fit, exit) for the same
law and settings or, with ``--pool N``, N evaluations of the law one after the other through a
one-slot ``SandboxPool`` (as a search evaluates its candidates), alternating between the two
checkouts round by round so that both see the same machine load, and prints each round, the
medians and their ratio. The other checkout is typically a worktree of an earlier commit
(``git worktree add /tmp/before HEAD~5``); both run with this interpreter, each with its own
tree first on ``PYTHONPATH``. Usage::

    python benchmarks/evaluate_against.py --baseline /tmp/before --task elastic \\
        --law examples/laws/neo_hookean.py --epochs 1 --rounds 3
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]


def run_once(tree: Path, args: argparse.Namespace) -> tuple[float, dict]:
    """Wall time of one ``sga-agent evaluate`` from ``tree``, and the evaluation it printed."""
    command = [sys.executable, "-c", "from sga_agent.cli import main; main()", "evaluate",
               "--task", args.task,
               str(args.law), "--epochs", str(args.epochs), "--json",
               *[f"--option={option}" for option in args.option]]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(tree)}
    start = time.perf_counter()
    done = subprocess.run(command, cwd=tree, env=env, capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - start
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    if not lines:
        raise SystemExit(f"{tree}: no evaluation printed\n{done.stderr[-2000:]}")
    return seconds, json.loads(lines[-1])


POOL_PROGRAM = """
import sys, time
from sga_agent.options import parse_options
from sga_agent.registry import load_task
from sga_agent.sandbox import SandboxLimits, SandboxPool
from sga_agent.task import EvaluationSettings
task, law, epochs, count = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
raw = dict(option.split("=", 1) for option in sys.argv[5:])
options = parse_options(load_task(task).options_type, raw, task)  # as the checkout reads them
settings = EvaluationSettings(epochs=epochs, options=options)
code = open(law).read()
start = time.perf_counter()
with SandboxPool(1, SandboxLimits()) as pool:
    evaluations = pool.map(task, [code] * count, settings)
print({"loss": evaluations[-1].loss, "status": evaluations[-1].status,
       "seconds": [round(e.seconds, 1) for e in evaluations]})
"""


def run_pool(tree: Path, args: argparse.Namespace) -> tuple[float, str]:
    """Wall time of ``args.pool`` evaluations through a one-slot pool from ``tree``."""
    options = [option if "=" in option else f"{option}=" for option in args.option]
    command = [sys.executable, "-c", POOL_PROGRAM, args.task, str(args.law), str(args.epochs),
               str(args.pool), *options]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(tree)}
    start = time.perf_counter()
    done = subprocess.run(command, cwd=tree, env=env, capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{tree}: the pool run failed\n{done.stderr[-2000:]}")
    return seconds, done.stdout.strip().splitlines()[-1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", type=Path, required=True, help="the other checkout")
    parser.add_argument("--task", default="elastic")
    parser.add_argument("--law", type=Path, default=HERE / "examples/laws/neo_hookean.py")
    parser.add_argument("--epochs", type=int, default=1)
    parser.add_argument("--option", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--pool", type=int, default=0, help="evaluations through a pool")
    args = parser.parse_args()
    args.law = args.law.resolve()
    trees = {"this checkout": HERE, "baseline": args.baseline.resolve()}
    times: dict[str, list[float]] = {name: [] for name in trees}
    load = os.getloadavg()[0]
    for round_number in range(args.rounds):
        for name, tree in trees.items():
            if args.pool:
                seconds, outcome = run_pool(tree, args)
            else:
                seconds, evaluation = run_once(tree, args)
                outcome = f"loss {evaluation['loss']}, status {evaluation['status']}"
            times[name].append(seconds)
            print(f"round {round_number + 1}, {name}: {seconds:.1f} s, {outcome}")
    print(f"\nload average at start {load:.2f}, at end {os.getloadavg()[0]:.2f}")
    medians = {name: statistics.median(values) for name, values in times.items()}
    for name, median in medians.items():
        print(f"{name}: median {median:.1f} s over {args.rounds} rounds")
    print(f"this checkout / baseline: {medians['this checkout'] / medians['baseline']:.2f}")


if __name__ == "__main__":
    main()
