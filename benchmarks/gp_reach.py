"""Can the genetic programming's grammar reach the true laws? Their forms written as genomes,
fitted from poor starting values exactly as the search fits a proposal.

Each form is a genome of the GP grammar (never handed to the search) whose constants start
away from the truth, inside the ranges random generation draws from; each is written to code
by the GP's own code generator and scored with ``sga-agent evaluate`` (the search's checks,
capture and fit, L-BFGS as the GP's runs use), next to the true law of ``examples/laws``.
Run from the repository root::

    python benchmarks/gp_reach.py --out-dir /tmp/reach                  # every form
    python benchmarks/gp_reach.py --out-dir /tmp/reach --only von-mises --epochs 5

Prints, per form, the fitted loss and the true law's, and writes ``results.json``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from tasks.constitutive.gp.codegen import law_code
from tasks.constitutive.gp.genome import Genome, Node, Param, Term, fits


def N(op: str, *children: Node | Param) -> Node:
    return Node(op, children)


EPS = N("eps")
DEV, VOL = N("dev", EPS), N("vol", EPS)
START_WEIGHT = Param("sigmoid", 2.0)  # 0.88: inside the earlier plastic terms' range (-1, 3)
UNIT_WEIGHT = Param("unit", 1.1)  # min(raw, 1): the correction replaces F


def radial_return(radius: Node, volumetric: Node = VOL) -> Node:
    """F rebuilt from the volumetric strain plus the deviatoric strain clamped to ``radius``."""
    return N("from_strain", N("add", volumetric, N("shrink", DEV, radius)))


#: name -> (task, genome at its poor start, the true law's file)
FORMS: dict[str, tuple[str, Genome, str]] = {
    # von Mises: a constant yield radius, starting at 0.135 (the truth's is 0.036)
    "von-mises": ("plasticine", Genome("plastic", (
        Term(START_WEIGHT, radial_return(N("const", Param("log", -2.0)))),)), "von_mises.py"),
    # the same from 1.0, above every strain of the scene: no particle yields at the start
    "von-mises-far": ("plasticine", Genome("plastic", (
        Term(START_WEIGHT, radial_return(N("const", Param("log", 0.0)))),)), "von_mises.py"),
    # Drucker-Prager: a radius proportional to the compression (slope -1, the truth's -0.54);
    # under expansion the volumetric part is dropped too (the apex: eps = 0)
    "drucker-prager": ("granular", Genome("plastic", (
        Term(START_WEIGHT, radial_return(N("scale", Param("linear", -1.0), N("sum", EPS)),
                                         N("neg", VOL))),)), "drucker_prager.py"),
    # fluid: J^(1/3) I, the exponent starting at 1/2
    "fluid": ("fluid", Genome("plastic", (Term(START_WEIGHT, N("smul", N("exp", N(
        "scale", Param("linear", 0.5), N("log_J"))), N("I"))),)), "fluid.py"),
    # fluid as J^(1/3) R: the same stress under an isotropic elastic law
    "fluid-rotated": ("fluid", Genome("plastic", (
        Term(START_WEIGHT, N("from_strain", VOL)),)), "fluid.py"),
    # the blocks, with a weight that reaches 1: von Mises from a radius of 0.135
    "von-mises-block": ("plasticine", Genome("plastic", (Term(UNIT_WEIGHT, N("from_strain", N(
        "cylinder", EPS, N("const", Param("log", -2.0))))),)), "von_mises.py"),
    # Drucker-Prager from a slope of e^-1 = 0.37 (the truth's 0.535)
    "drucker-prager-block": ("granular", Genome("plastic", (Term(UNIT_WEIGHT, N("from_strain", N(
        "cone", EPS, N("const", Param("log", -1.0))))),)), "drucker_prager.py"),
    # fluid as J^(1/3) R with its weight starting at 0.8
    "fluid-unit": ("fluid", Genome("plastic", (
        Term(Param("unit", 0.8), N("from_strain", VOL)),)), "fluid.py"),
    # neo-Hookean: mu (F F^T - I) + lam log J I, both moduli starting at e^10 (truth ~e^12)
    "neo-hookean": ("elastic", Genome("elastic", (
        Term(Param("log", 10.0), N("sub", N("matmul", N("F"), N("T", N("F"))), N("I"))),
        Term(Param("log", 10.0), N("smul", N("log_J"), N("I"))))), "neo_hookean.py"),
}  # fmt: skip


def evaluate(task: str, path: Path, epochs: int) -> dict:
    """``sga-agent evaluate --json`` of the law in ``path``, fitted with L-BFGS."""
    command = ["sga-agent", "evaluate", "--task", task, str(path), "--json",
               "--epochs", str(epochs), "--option", "optimizer=lbfgs"]  # fmt: skip
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    try:
        result = json.loads(done.stdout)
    except json.JSONDecodeError:
        return {"valid": False, "loss": None, "reason": done.stderr[-500:]}
    return {key: result.get(key) for key in ("valid", "loss", "parameters", "reason")}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out-dir", type=Path, required=True)
    parser.add_argument("--only", nargs="*", choices=sorted(FORMS), default=sorted(FORMS))
    parser.add_argument("--epochs", type=int, default=5)
    parser.add_argument("--jobs", type=int, default=2, help="evaluations at once")
    args = parser.parse_args(argv)
    args.out_dir.mkdir(parents=True, exist_ok=True)
    jobs: dict[str, tuple[str, Path]] = {}
    for name in args.only:
        task, genome, truth = FORMS[name]
        assert fits(genome), name
        path = args.out_dir / f"{name}.py"
        path.write_text(law_code(genome))
        jobs[name] = (task, path)
        jobs[f"truth:{task}"] = (task, Path("examples/laws") / truth)
    with ThreadPoolExecutor(args.jobs) as pool:
        futures = {name: pool.submit(evaluate, *job, args.epochs) for name, job in jobs.items()}
        results = {name: future.result() for name, future in futures.items()}
    (args.out_dir / "results.json").write_text(json.dumps(results, indent=1))
    for name in args.only:
        task = FORMS[name][0]
        loss, truth = results[name]["loss"], results[f"truth:{task}"]["loss"]
        ratio = f"{loss / truth:.3g}x" if loss is not None and truth else "-"
        print(f"{name:16s} {task:10s} loss {loss}  truth {truth}  ({ratio})", file=sys.stdout)


if __name__ == "__main__":
    main()
