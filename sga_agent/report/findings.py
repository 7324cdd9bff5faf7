"""What a run found, in numbers: the facts that lead its report and go into ``summary.json``
and ``sga-agent report --json``.

The search-side facts (best and seed losses, the best solution with its fitted constants)
come from the run folder; what only the task knows (the ground truth, the true law's loss,
the free run) comes from its optional ``assess`` method (see :class:`sga_agent.task.Task`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from sga_agent.fingerprint import fingerprint
from sga_agent.report.data import Candidate, Run
from sga_agent.run_store import SEED
from sga_agent.task import Assessment, solution_with_parameters

TOP = 3
HARTREE_IN_EV = 27.211386245988


@dataclass
class Findings:
    """The numbers a reader judges a run by (see :func:`find`)."""

    best: Candidate | None
    seed: Candidate | None
    best_code: str = ""
    assessment: Assessment | None = None
    assessment_error: str = ""
    molecules: list[dict[str, Any]] = field(default_factory=list)
    duration_s: float | None = None

    @property
    def seed_over_best(self) -> float | None:
        """How many times the best loss is below the seed's (None without both)."""
        if self.best is None or self.seed is None or self.seed.status != "ok":
            return None
        return _ratio(self.seed.loss, self.best.loss)

    @property
    def best_over_truth(self) -> float | None:
        """How many times the best loss is above the true law's (None when unknown)."""
        truth = self.assessment.truth_loss if self.assessment else None
        if self.best is None or truth is None:
            return None
        return _ratio(self.best.loss, truth)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready; keys with no value are None."""
        assessment = self.assessment.to_dict() if self.assessment else {}
        return {
            "best": _brief(self.best),
            "seed": _brief(self.seed),
            "seed_over_best": self.seed_over_best,
            "truth": assessment.get("truth") or None,
            "truth_loss": assessment.get("truth_loss"),
            "best_over_truth": self.best_over_truth,
            "best_solution": self.best_code or None,
            "parameters": self.best.parameters if self.best else {},
            "derived": assessment.get("derived", {}),
            "free_run": assessment.get("free_run"),
            "assessment_error": self.assessment_error or None,
            "molecules": self.molecules,
            "duration_s": self.duration_s,
        }


def _ratio(numerator: float, denominator: float) -> float | None:
    if not (math.isfinite(numerator) and math.isfinite(denominator)) or denominator <= 0:
        return None
    return numerator / denominator


def _brief(candidate: Candidate | None) -> dict[str, Any] | None:
    if candidate is None:
        return None
    loss = candidate.loss if math.isfinite(candidate.loss) else "inf"
    return {"candidate": candidate.id, "loss": loss, "status": candidate.status}


def law_key(task: object | None, candidate: Candidate) -> str:
    """What makes two candidates the same solution for "distinct": the SMILES of a molecule,
    else the fingerprint of the code with every fitted parameter's starting value set to 0
    (so that children that differ from their parent only in where its fit started count as
    one law)."""
    if candidate.extras.get("smiles"):
        return "smiles:" + str(candidate.extras["smiles"])
    zeros = dict.fromkeys(candidate.parameters, 0.0)
    return fingerprint(solution_with_parameters(task, candidate.code, zeros))


def distinct(run: Run, task: object | None, count: int = TOP) -> list[Candidate]:
    """The best ``count`` scored candidates, one per distinct solution (:func:`law_key`)."""
    seen: set[str] = set()
    found = []
    for candidate in run.ranked():
        key = law_key(task, candidate)
        if key not in seen:
            seen.add(key)
            found.append(candidate)
        if len(found) == count:
            break
    return found


def find(run: Run, task: object | None, simulate: bool = True) -> Findings:
    """The findings of ``run``; ``task`` (None when it cannot be loaded) adds what it knows,
    ``simulate`` allows its free run. A failing assessment is recorded, not raised."""
    best = run.best
    seed = next((c for c in run.candidates if c.id == SEED), None)
    times = [c.time for c in run.candidates if c.time is not None]
    findings = Findings(
        best=best,
        seed=seed,
        best_code=solution_with_parameters(task, best.code, best.parameters) if best else "",
        duration_s=max(times) - run.started if times and run.started is not None else None,
    )
    assess = getattr(task, "assess", None)
    if best is not None and assess is not None:
        options = dict(run.config.get("task_options") or {})
        try:
            findings.assessment = assess(best.artifacts(), best.parameters, options, simulate)
        except Exception as error:  # any failure of the task's check loses only these facts
            findings.assessment_error = f"{type(error).__name__}: {error}"
    findings.molecules = [m for m in map(molecule_facts, distinct(run, task)) if m]
    return findings


def molecule_facts(candidate: Candidate) -> dict[str, Any]:
    """A molecule's property on the QM9 scale and its distance to the target (empty for a
    candidate that is no molecule)."""
    extras, parameters = candidate.extras, candidate.parameters
    if "smiles" not in extras or "property" not in parameters or "target" not in extras:
        return {}
    value, target = float(parameters["property"]), float(extras["target"])
    hartree = _hartree(str(extras.get("property_name")), value)
    return {
        "candidate": candidate.id,
        "smiles": extras["smiles"],
        "property": extras.get("property_name", "property"),
        "normalized": value,
        "target": target,
        "distance": abs(value - target),
        "hartree": hartree,
        "ev": None if hartree is None else hartree * HARTREE_IN_EV,
        "loss": candidate.loss,
    }


def _hartree(label: str, normalized: float) -> float | None:
    """The normalized value back in Hartree on the QM9 B3LYP scale (QM9 mean + value x std);
    None for a property the molecule tasks do not name."""
    from tasks.molecules.calibration import PROPERTY_LABELS, QM9_STATISTICS

    key = {name: key for key, name in PROPERTY_LABELS.items()}.get(label)
    if key is None:
        return None
    stats = QM9_STATISTICS[key]
    return stats.mean + normalized * stats.std
