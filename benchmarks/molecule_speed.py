"""Speed of the molecule tasks: seconds per candidate evaluation and per gradient step.

Evaluates well-known drugs (``tasks.molecules.examples.DRUG_LIKE``, 11 to 37 heavy atoms) as
proposals of the ``homo`` task with the default settings (30 Adam steps), their coordinates an
RDKit conformer, and prints for each the wall time of the whole evaluation and of one gradient
step (GFN1-xTB forward and backward on all atoms). It then times gradient steps of a few molecules
with 1 and with 2 torch threads. The goal is under 15 s per candidate on a 2-core CPU.

Usage::

    python benchmarks/molecule_speed.py                  # all 20 molecules, 1 thread
    python benchmarks/molecule_speed.py --molecules 5 --steps 10
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch


def conformer_solution(smiles: str, seed: int = 1) -> str:
    """Solution text for ``smiles`` with an ETKDG + MMFF heavy-atom conformer."""
    from rdkit import Chem
    from rdkit.Chem import AllChem

    from tasks.molecules.solution import format_solution

    mol = Chem.AddHs(Chem.MolFromSmiles(smiles))
    AllChem.EmbedMolecule(mol, randomSeed=seed)
    AllChem.MMFFOptimizeMolecule(mol)
    heavy = mol.GetConformer().GetPositions()[: mol.GetNumHeavyAtoms()]
    return format_solution(smiles, heavy.tolist())


def gradient_step_seconds(smiles: str, repeats: int = 5) -> tuple[int, int, float]:
    """(heavy atoms, atoms, mean seconds of one xTB forward + backward) for ``smiles``."""
    from tasks.molecules.geometry import build_structure
    from tasks.molecules.inner_loop import Objective
    from tasks.molecules.solution import parse_solution
    from tasks.molecules.validation import check_proposal
    from tasks.molecules.xtb import BOHR_PER_ANGSTROM, DTYPE, HARTREE_IN_KCAL_MOL, GFN1Model

    checked = check_proposal(parse_solution(conformer_solution(smiles)))
    structure = build_structure(checked)
    model = GFN1Model(structure.numbers.tolist())
    objective = Objective("homo", 0.0)
    x = torch.tensor(structure.positions, dtype=DTYPE, requires_grad=True)
    times = []
    for _ in range(repeats + 1):
        started = time.perf_counter()
        point = model(x * BOHR_PER_ANGSTROM)
        loss = (objective.normalized(point) - objective.target) ** 2
        loss = loss + objective.strain_weight * HARTREE_IN_KCAL_MOL * point.energy
        loss.backward()
        times.append(time.perf_counter() - started)
        with torch.no_grad():
            x.add_(1e-3 * torch.randn_like(x))
        x.grad = None
    return structure.n_heavy, len(structure.numbers), statistics.mean(times[1:])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--molecules", type=int, default=20, help="how many (at most 20)")
    parser.add_argument("--steps", type=int, default=None, help="Adam steps (default 30)")
    parser.add_argument("--task", default="homo", help="homo, lumo, gap or gap-low")
    args = parser.parse_args(argv)

    torch.set_num_threads(1)
    started = time.perf_counter()
    import dxtb  # noqa: F401  (import cost reported separately)
    import rdkit  # noqa: F401

    from sga_agent.registry import load_task
    from sga_agent.task import EvaluationSettings
    from tasks.molecules.examples import DRUG_LIKE

    print(f"imports (torch, RDKit, dxtb): {time.perf_counter() - started:.1f} s")
    task = load_task(args.task)
    settings = EvaluationSettings(epochs=args.steps)
    names = list(DRUG_LIKE)[: args.molecules]

    print(f"\nTask {task.name!r}, 1 torch thread, {args.steps or 30} Adam steps per candidate:")
    print(f"{'molecule':18s} {'heavy':>5s} {'atoms':>5s} {'eval s':>7s} {'step s':>7s}  property")
    eval_times, failures = [], []
    for name in names:
        smiles = DRUG_LIKE[name]
        evaluation = task.evaluate(task.capture(conformer_solution(smiles)), settings)
        heavy, atoms, step = gradient_step_seconds(smiles)
        eval_times.append(evaluation.seconds)
        if not evaluation.valid:
            failures.append(f"{name}: {evaluation.reason}")
            summary = "INVALID: " + evaluation.reason
        else:
            summary = (
                f"{evaluation.extras['property_initial']:+.3f} -> "
                f"{evaluation.parameters['property']:+.3f} (strain "
                f"{evaluation.parameters['strain_kcal_mol']:.2f} kcal/mol, loss "
                f"{evaluation.loss:.3f})"
            )
        print(
            f"{name:18s} {heavy:5d} {atoms:5d} {evaluation.seconds:7.2f} {step:7.3f}  {summary}",
            flush=True,
        )
    print(
        f"\nper candidate: mean {statistics.mean(eval_times):.2f} s, max {max(eval_times):.2f} s"
        f" over {len(names)} molecules; {len(names) - len(failures)} valid"
    )
    for failure in failures:
        print("  failed:", failure)

    print("\nGradient step (forward + backward), 1 vs 2 torch threads:")
    for name in ("paracetamol", "diazepam", "imatinib"):
        row = []
        for threads in (1, 2):
            torch.set_num_threads(threads)
            heavy, atoms, step = gradient_step_seconds(DRUG_LIKE[name])
            row.append(step)
        print(
            f"  {name:14s} ({atoms:3d} atoms): 1 thread {row[0]:.3f} s, 2 threads {row[1]:.3f} s"
            f" (x{row[1] / row[0]:.1f})"
        )
    torch.set_num_threads(1)
    return 1 if failures else 0


if __name__ == "__main__":
    raise SystemExit(main())
