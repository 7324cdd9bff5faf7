"""The genetic programming's search power at a fixed evaluation budget, two ways.

``proxy``: the search loop of ``sga-agent search`` (the seed, then per iteration the top-K as
parents, --exploit children at 0.5 and --explore at 1.0, the search's proposal seeds) with the
simulation replaced by a regression on the true law: trial deformation gradients F near the
identity (spread 0.15, half of them compressed by 10%), a law's constants fitted by L-BFGS (6
evaluations, as the quick preset's fit) to the true law's corrected F, or for ``elastic`` its
Kirchhoff stress (``examples/laws``); the loss is the mean squared error relative to the
identity's, or to a zero stress's (the plastic seed scores 1, the true law 0). Seconds per run,
so many seeds. It does not model instability.

``search``: ``sga-agent search`` itself with a fixed budget (the quick preset), reporting the
best loss over the true law's (the run's ``summary.json``). Minutes per evaluation.

Either runs whatever proposer ``tasks.constitutive.gp`` imports, so an older one is measured
with ``PYTHONPATH`` pointing at a worktree of an earlier commit. From the repository root::

    python benchmarks/gp_search.py proxy --task plasticine --seeds 0-19 --max-evaluations 40
    python benchmarks/gp_search.py search --task granular --seeds 0 --max-evaluations 25 \
        --out-dir /tmp/gp-runs --search-args "--option steps=200"
"""

from __future__ import annotations

import argparse
import inspect
import json
import math
import shlex
import statistics
import subprocess
import sys
from pathlib import Path

import torch

from bridges.linalg import stable_linalg
from sga_agent.parsing import parse_response
from sga_agent.task import Parent
from tasks.constitutive import prompt_text
from tasks.constitutive.gp import GeneticProgrammingProposer
from tasks.constitutive.law_code import load_law

TRUTHS = {"plasticine": "von_mises.py", "granular": "drucker_prager.py", "fluid": "fluid.py",
          "imaginary": "mixture.py", "elastic": "neo_hookean.py"}  # fmt: skip
#: What each task's law maps: F to the Kirchhoff stress, or F to the corrected F.
SEARCHED = {task: "elastic" if task == "elastic" else "plastic" for task in TRUTHS}
#: Loss and gradient evaluations of a fit, as the quick preset's 5 L-BFGS epochs take.
FIT_EVALUATIONS = 6
QUICK = {"iterations": 4, "top_k": 5, "exploit": 2, "explore": 4}


def samples(seed: int = 0, batch: int = 256) -> torch.Tensor:
    """Trial F near the identity; the second half compressed by 10% (for pressure-dependence)."""
    generator = torch.Generator().manual_seed(seed)
    F = torch.eye(3, dtype=torch.float64) + 0.15 * torch.randn(
        batch, 3, 3, generator=generator, dtype=torch.float64
    )
    F[batch // 2 :] *= 0.9
    return F


class Proxy:
    """Scores law code by the regression on one task's true law: the corrected F of a plastic
    law, relative to the identity's error (no correction), or the Kirchhoff stress of an
    elastic one, relative to the zero stress's error."""

    def __init__(self, task: str) -> None:
        truth = load_law((Path("examples/laws") / TRUTHS[task]).read_text(), torch.float64)
        self.F = samples()
        with torch.no_grad(), stable_linalg():
            self.target = truth(self.F)
        reference = self.F if SEARCHED[task] == "plastic" else torch.zeros_like(self.target)
        self.scale = ((reference - self.target) ** 2).mean().item()

    def loss(self, code: str) -> tuple[float, dict[str, float]]:
        """Fitted relative loss and the fitted raw parameters (inf when the law fails)."""
        try:
            law = load_law(code, torch.float64)
            parameters = list(law.parameters())

            def closure() -> torch.Tensor:
                optimizer.zero_grad()
                value = ((law(self.F) - self.target) ** 2).mean() / self.scale
                if value.requires_grad:
                    value.backward()
                return value

            with stable_linalg():
                if parameters:
                    optimizer = torch.optim.LBFGS(
                        parameters, lr=1.0, max_iter=FIT_EVALUATIONS, max_eval=FIT_EVALUATIONS,
                        tolerance_grad=0.0, tolerance_change=0.0, line_search_fn="strong_wolfe",
                    )  # fmt: skip
                    optimizer.step(closure)
                with torch.no_grad():
                    loss = (((law(self.F) - self.target) ** 2).mean() / self.scale).item()
        except Exception:  # noqa: BLE001 - a failing law scores inf, as an invalid candidate
            return math.inf, {}
        fitted = {name: p.item() for name, p in law.named_parameters()}
        return (loss if math.isfinite(loss) else math.inf), fitted


def proxy_run(task: str, seed: int, budget: int, loop: dict[str, int]) -> float:
    """Best relative loss of one proxy search of ``budget`` evaluations (seed included)."""
    proxy = Proxy(task)
    proposer = GeneticProgrammingProposer(SEARCHED[task])
    elastic = SEARCHED[task] == "elastic"
    seed_code = prompt_text.ELASTIC_SEED if elastic else prompt_text.PLASTIC_SEED
    heap = [Parent(seed_code, *proxy.loss(seed_code))]
    tried: list[str] = []
    remembers = "tried" in inspect.signature(proposer.propose_from).parameters
    evaluations = 1
    for iteration in range(1, loop["iterations"] + 1):
        parents = sorted(heap, key=lambda p: p.loss)[: loop["top_k"]]
        for temperature, n in ((0.5, loop["exploit"]), (1.0, loop["explore"])):
            n = min(n, budget - evaluations)
            if n <= 0:
                break
            call_seed = (seed * 1_000_003 + iteration) * 1009 + round(temperature * 100)
            memory = {"tried": list(tried)} if remembers else {}  # an older proposer has none
            answers = proposer.propose_from(parents, temperature, n, call_seed, **memory)
            tried += answers
            for answer in answers:
                code = parse_response(answer).code
                loss, fitted = proxy.loss(code)
                heap.append(Parent(code, loss, fitted))
                evaluations += 1
    return min(p.loss for p in heap)


def seeds(text: str) -> list[int]:
    """``3`` or ``0-19`` or ``0,4,5``."""
    found: list[int] = []
    for part in text.split(","):
        low, _, high = part.partition("-")
        found += range(int(low), int(high or low) + 1)
    return found


def search_run(task: str, seed: int, budget: int, out_dir: Path, extra: list[str]) -> dict:
    """One ``sga-agent search`` run's ``summary.json`` (its best loss and the true law's)."""
    run_root = out_dir / f"{task}-{seed}"
    command = ["sga-agent", "search", "--task", task, "--seed", str(seed), "--max-evaluations",
               str(budget), "--out-dir", str(run_root), *extra]  # fmt: skip
    subprocess.run(command, check=True, capture_output=True)
    summary = json.loads(next(run_root.glob("*/summary.json")).read_text())
    return summary


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mode", choices=["proxy", "search"])
    parser.add_argument("--task", choices=sorted(TRUTHS), required=True)
    parser.add_argument("--seeds", type=seeds, default=[0])
    parser.add_argument("--max-evaluations", type=int, default=25)
    parser.add_argument("--iterations", type=int, help="proxy: outer iterations (else enough)")
    parser.add_argument("--out-dir", type=Path, default=Path("gp_runs"))
    parser.add_argument("--search-args", default="", help="search: more options, one string")
    args = parser.parse_args(argv)
    if args.mode == "proxy":
        per_iteration = QUICK["exploit"] + QUICK["explore"]
        iterations = args.iterations or math.ceil((args.max_evaluations - 1) / per_iteration)
        loop = {**QUICK, "iterations": iterations}
        best = [proxy_run(args.task, s, args.max_evaluations, loop) for s in args.seeds]
        solved = sum(loss < 1e-3 for loss in best)
        print(f"{args.task}: best relative loss over seeds {args.seeds[0]}-{args.seeds[-1]}: "
              f"median {statistics.median(best):.3g}, geometric mean "
              f"{math.exp(statistics.fmean(math.log(max(b, 1e-12)) for b in best)):.3g}, "
              f"below 1e-3 in {solved}/{len(best)}")  # fmt: skip
        print(" ".join(f"{b:.3g}" for b in best))
        return
    for s in args.seeds:
        extra = shlex.split(args.search_args)
        summary = search_run(args.task, s, args.max_evaluations, args.out_dir, extra)
        found = summary["findings"]
        counts = {key: summary[key] for key in ("valid", "evaluations")}
        losses = {"best": found["best"]["loss"], "truth": found["truth_loss"]}
        print(json.dumps({"seed": s, **counts, **losses, "ratio": found["best_over_truth"]}))


if __name__ == "__main__":
    sys.exit(main())
