"""Scoring one proposal: parse, validate, build the 3D structure, run the inner loop, report."""

from __future__ import annotations

import time

from sga_agent.task import Evaluation, EvaluationSettings
from tasks.molecules.calibration import PROPERTY_LABELS
from tasks.molecules.constants import DEFAULT_LEARNING_RATE, DEFAULT_STEPS
from tasks.molecules.feedback import describe, normalized_values
from tasks.molecules.geometry import build_structure
from tasks.molecules.inner_loop import Objective, run_inner_loop
from tasks.molecules.options import MoleculeOptions
from tasks.molecules.solution import ProposalError, parse_solution
from tasks.molecules.validation import InvalidMolecule, check_proposal
from tasks.molecules.xtb import XtbError


def objective_for(prop: str, target: float, settings: EvaluationSettings) -> Objective:
    """The inner-loop objective of a task under ``settings`` (option ``strain_weight``)."""
    weight = settings.options_as(MoleculeOptions).strain_weight
    return Objective(prop=prop, target=target, strain_weight=float(weight))


def evaluate_solution(
    solution: str, prop: str, target: float, settings: EvaluationSettings
) -> Evaluation:
    """Score ``solution`` for the target ``prop`` = ``target``; never raises for a bad candidate.

    ``settings.epochs`` is the number of Adam steps (default :data:`DEFAULT_STEPS`),
    ``settings.learning_rate`` the Adam step size in Angstrom, ``settings.seed`` seeds the
    fallback conformer. ``Evaluation.loss`` is the total loss (property loss plus conformer
    loss) of the best step. Failures: status "invalid" for an unreadable or chemically invalid
    proposal, "unstable" when xTB fails on the starting structure (no SCF convergence,
    non-finite values), "error" for an unexpected exception.
    """
    started = time.perf_counter()
    objective = objective_for(prop, target, settings)
    steps = DEFAULT_STEPS if settings.epochs is None else settings.epochs
    learning_rate = settings.learning_rate or DEFAULT_LEARNING_RATE

    def invalid(reason: str, status: str = "invalid") -> Evaluation:
        reason = " ".join(reason.split())  # one line, whatever a library put in its message
        return Evaluation.invalid(reason, status=status, seconds=time.perf_counter() - started)

    try:
        proposal = parse_solution(solution)
        checked = check_proposal(proposal)
        structure = build_structure(checked, seed=settings.seed)
    except (ProposalError, InvalidMolecule) as error:
        return invalid(str(error))
    except Exception as error:  # RDKit can fail in unforeseen ways on odd input
        return invalid(
            f"the molecule could not be processed ({type(error).__name__}: {error})", "error"
        )
    try:
        trajectory = run_inner_loop(structure, objective, steps, learning_rate)
    except XtbError as error:
        return invalid(f"GFN1-xTB could not be run on this molecule: {error}", "unstable")
    except Exception as error:
        return invalid(
            f"the property calculation failed ({type(error).__name__}: {error})", "error"
        )

    best = trajectory.best
    record = trajectory.records[best]
    values = normalized_values(record)
    heavy = structure.n_heavy
    parameters = {
        "property": record.property,
        **values,
        "strain_kcal_mol": float(trajectory.strain[best]),
        "property_loss": float(trajectory.property_loss[best]),
        "conformer_loss": float(trajectory.conformer_loss[best]),
    }
    extras = {
        "smiles": checked.smiles,
        "input_smiles": proposal.smiles,
        "property_name": PROPERTY_LABELS[prop],
        "target": target,
        "property_initial": trajectory.records[0].property,
        "coordinates": record.positions[:heavy].round(4).tolist(),
        "coordinates_initial": structure.heavy_positions.round(4).tolist(),
        "geometry_source": structure.source,
        "geometry_note": structure.note,
        "force_field": structure.force_field,
        "rmsd_from_proposal": structure.rmsd,
        "heavy_atoms": heavy,
        "atoms": int(len(structure.numbers)),
        "best_step": best,
        "steps": len(trajectory.records) - 1,
        "learning_rate": learning_rate,
        "strain_weight": objective.strain_weight,
        "stopped": trajectory.stopped,
    }
    curves = {
        "loss": trajectory.total_loss.tolist(),
        "property": [r.property for r in trajectory.records],
        "strain": trajectory.strain.tolist(),
        "property_loss": trajectory.property_loss.tolist(),
        "conformer_loss": trajectory.conformer_loss.tolist(),
    }
    return Evaluation(
        valid=True,
        loss=float(trajectory.total_loss[best]),
        feedback=describe(checked.smiles, structure, trajectory),
        parameters=parameters,
        curves=curves,
        extras=extras,
        seconds=time.perf_counter() - started,
    )
