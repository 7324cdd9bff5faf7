"""What a run found, in numbers: the facts that lead its report and go into ``summary.json``
and ``sga-agent report --json``.

The search-side facts (best and seed losses, the best solution with its fitted constants)
come from the run folder; what only the task knows comes from its hooks (see
:class:`sga_agent.task.TaskBase`): the ground truth, the true law's loss and the free run from
``assess``, facts about the top distinct solutions (a molecule's property in eV) from
``top_facts``. What the run recorded at its start (the task's ``provenance``: an observation's
hash, the truth it read) is compared with what the task gives now; the task assesses with the
recorded one (``with_provenance``).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any

from sga_agent.fingerprint import fingerprint
from sga_agent.options import options_from_data
from sga_agent.report.data import Candidate, Run
from sga_agent.run_store import SEED
from sga_agent.task import (
    Assessment,
    FormComparison,
    Simplified,
    Task,
    as_task,
    has_hook,
    solution_with_parameters,
)

TOP = 3
#: What a run whose time budget was spent says of the work it left to the report.
DEFERRED = ("the time budget was spent before the forms were compared and the best simplified; "
            "`sga-agent report` does both")
#: The best distinct forms handed to the task's ``compare_forms`` (those within its noise run
#: on its probe scenes).
FORMS = 6


@dataclass
class Findings:
    """The numbers a reader judges a run by (see :func:`find`)."""

    best: Candidate | None
    seed: Candidate | None
    best_code: str = ""
    best_formula: str = ""  # the task's formula of the best (Task.formula), if it writes one
    assessment: Assessment | None = None
    assessment_error: str = ""
    forms: FormComparison | None = None
    forms_error: str = ""
    simplified: Simplified | None = None
    simplified_error: str = ""
    top_facts: list[dict[str, Any]] = field(default_factory=list)
    duration_s: float | None = None
    changed: list[str] = field(default_factory=list)  # provenance that differs from the start's
    #: The comparison of forms and the simplification were left out: the run's time budget
    #: was spent (``sga-agent report`` does them).
    deferred: bool = False

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
            "best_formula": self.best_formula or None,
            "parameters": self.best.parameters if self.best else {},
            "derived": assessment.get("derived", {}),
            "free_run": assessment.get("free_run"),
            "held_out": assessment.get("held_out"),
            "verdict": assessment.get("verdict") or None,
            "identifiability": self.forms.to_dict() if self.forms else None,
            "identifiability_error": self.forms_error or None,
            "simplified": self.simplified.to_dict() if self.simplified else None,
            "simplified_error": self.simplified_error or None,
            "changed_since_start": self.changed,
            "assessment_error": self.assessment_error or None,
            "molecules": self.top_facts,  # the key summary.json has always had
            "duration_s": self.duration_s,
            "deferred": DEFERRED if self.deferred else None,
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


def changes(recorded: dict[str, Any], now: dict[str, Any]) -> list[str]:
    """What differs between the provenance a run recorded at its start and the task's now,
    one "key: recorded at the start, now" text each (long values shortened)."""
    return [
        f"{key}: {_short(recorded.get(key))} at the start, {_short(now.get(key))} now"
        for key in sorted(set(recorded) | set(now))
        if recorded.get(key) != now.get(key)
    ]


def _short(value: Any, width: int = 120) -> str:
    text = json.dumps(value, default=str)
    return text if len(text) <= width else text[: width - 3] + "..."


def law_key(task: Task | None, candidate: Candidate) -> str:
    """What makes two candidates the same solution for "distinct": the task's own
    ``solution_key`` (a molecule's SMILES), else the fingerprint of the code with every fitted
    parameter's starting value set to 0 (so that children that differ from their parent only
    in where its fit started count as one law)."""
    own = as_task(task).solution_key(candidate) if task is not None else None
    if own is not None:
        return own
    zeros = dict.fromkeys(candidate.parameters, 0.0)
    return fingerprint(solution_with_parameters(task, candidate.code, zeros))


def distinct(run: Run, task: Task | None, count: int = TOP) -> list[Candidate]:
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


def find(
    run: Run, task: Task | None, options: Any = None, simulate: bool = True, compare: bool = True
) -> Findings:
    """The findings of ``run``; ``task`` (None when it cannot be loaded) adds what it knows,
    given the run's ``options`` (its options object; None: built from the run's config),
    ``simulate`` allows its free run and, with ``compare``, the comparison of the forms that
    fit equally on the task's probe scenes (``compare_forms``) and the simplification of the
    best; without ``compare`` the findings say they were left out (``deferred``). A failing
    assessment is recorded, not raised."""
    best = run.best
    seed = next((c for c in run.candidates if c.id == SEED), None)
    times = [c.time for c in run.candidates if c.time is not None]
    findings = Findings(
        best=best,
        seed=seed,
        best_code=solution_with_parameters(task, best.code, best.parameters) if best else "",
        duration_s=max(times) - run.started if times and run.started is not None else None,
    )
    if task is None:
        return findings
    task = as_task(task)
    if best is not None:
        try:
            findings.best_formula = task.formula(best.code, best.parameters)
        except Exception:  # a formula is a courtesy: its failure loses only it
            findings.best_formula = ""
    forms = distinct(run, task, FORMS)  # each candidate's key computed once
    if best is not None:
        try:
            if options is None:
                recorded = run.config.get("task_options") or {}
                options = options_from_data(task.options_type, recorded, task.name)
            assessed = task
            if run.provenance is not None:
                findings.changed = changes(run.provenance, task.provenance(options))
                assessed = as_task(task.with_provenance(run.provenance))
            findings.assessment = assessed.assess(
                best.artifacts(), best.parameters, options, simulate
            )
        except Exception as error:  # any failure of the task's check loses only these facts
            findings.assessment_error = f"{type(error).__name__}: {error}"
        findings.deferred = simulate and not compare and any(
            has_hook(assessed, hook) for hook in ("compare_forms", "simplify"))
        if simulate and compare and findings.assessment is not None and not findings.changed:
            try:
                findings.forms = assessed.compare_forms(forms, options, run.path)
            except Exception as error:  # as the assessment's
                findings.forms_error = f"{type(error).__name__}: {error}"
            try:
                findings.simplified = assessed.simplify(best, options)
            except Exception as error:  # as the assessment's
                findings.simplified_error = f"{type(error).__name__}: {error}"
    findings.top_facts = task.top_facts(forms[:TOP])  # the first TOP distinct ones
    return findings
