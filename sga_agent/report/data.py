"""A run folder read back into plain records (no task imports, no simulator)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sga_agent.config import current_format
from sga_agent.events import CandidateEvaluated, ProposalReceived, SandboxReady
from sga_agent.heap import ranked_loss
from sga_agent.run_store import CONFIG, SUMMARY, RunStore


@dataclass
class Candidate:
    """One evaluated candidate, from ``candidates/<id>/``."""

    id: str
    status: str
    loss: float
    reason: str = ""
    parameters: dict[str, float] = field(default_factory=dict)
    extras: dict[str, Any] = field(default_factory=dict)
    code: str = ""
    feedback: str = ""
    curves: dict[str, list[float]] = field(default_factory=dict)
    folder: Path | None = None
    time: float | None = None  # when its evaluation was recorded (seconds since the epoch)

    def artifacts(self) -> dict[str, Any]:
        """What the trusted fit left for reports (read when asked: it can be large)."""
        return _read_json(self.folder / "artifacts.json", {}) if self.folder else {}

    @property
    def iteration(self) -> int:
        """The search iteration, from the id's prefix (``00-seed`` is iteration 0)."""
        return int(self.id.split("-", 1)[0])


@dataclass
class Run:
    """What a report needs from a run folder."""

    path: Path
    config: dict[str, Any]
    candidates: list[Candidate]
    sandbox: dict[str, Any] | None = None
    summary: dict[str, Any] | None = None
    tokens: int = 0
    cost_usd: float = 0.0
    started: float | None = None  # the first event's time (seconds since the epoch)
    provenance: dict[str, Any] | None = None  # what the task recorded at the start

    @property
    def task(self) -> str:
        return str(self.config.get("task", "?"))

    @property
    def iterations(self) -> list[int]:
        """Iterations with at least one evaluated candidate, in order."""
        return sorted({candidate.iteration for candidate in self.candidates})

    @property
    def parsimony(self) -> float:
        """The run's :attr:`~sga_agent.config.LoopConfig.parsimony` (0 for runs before it)."""
        return float((self.config.get("loop") or {}).get("parsimony", 0.0))

    def ranked(self) -> list[Candidate]:
        """Scored candidates, best first, as the search ranked them (by loss, a fitted
        parameter costing :attr:`parsimony` of it); duplicates are left out."""
        scored = [
            c for c in self.candidates
            if c.status == "ok" and math.isfinite(c.loss) and "duplicate_of" not in c.extras
        ]  # fmt: skip
        return sorted(scored, key=lambda c: ranked_loss(c.loss, len(c.parameters), self.parsimony))

    @property
    def best(self) -> Candidate | None:
        ranked = self.ranked()
        return ranked[0] if ranked else None


def _read_json(path: Path, default: Any) -> Any:
    return json.loads(path.read_text(encoding="utf-8")) if path.is_file() else default


def _read_text(path: Path) -> str:
    return path.read_text(encoding="utf-8") if path.is_file() else ""


def read_candidate(folder: Path) -> Candidate | None:
    """The candidate in ``folder``, or None while it has no ``evaluation.json`` yet."""
    evaluation = _read_json(folder / "evaluation.json", None)
    if evaluation is None:
        return None
    return Candidate(
        id=folder.name,
        status=evaluation.get("status", "ok" if evaluation.get("valid") else "invalid"),
        loss=float(evaluation.get("loss", math.inf)),
        reason=evaluation.get("reason", ""),
        parameters=evaluation.get("parameters", {}),
        extras=evaluation.get("extras", {}),
        code=_read_text(folder / "code.py"),
        feedback=_read_text(folder / "feedback.txt"),
        curves=_read_json(folder / "curves.json", {}),
        folder=folder,
    )


def read_run(path: Path) -> Run:
    """Read the run folder at ``path``.

    Raises
    ------
    sga_agent.run_store.RunStoreError
        ``path`` is not a run folder.
    """
    store = RunStore.open(path)
    folders = sorted((store.path / "candidates").glob("*/"))
    candidates = [c for c in map(read_candidate, folders) if c is not None]
    run = Run(
        path=store.path,
        config=current_format(_read_json(store.path / CONFIG, {}).get("config", {})),
        candidates=candidates,
        summary=_read_json(store.path / SUMMARY, None),
        provenance=store.provenance(),
    )
    by_id = {candidate.id: candidate for candidate in candidates}
    for event in store.events():
        if run.started is None and isinstance(event.get("time"), int | float):
            run.started = float(event["time"])
        if event.get("type") == CandidateEvaluated.type and event.get("candidate") in by_id:
            by_id[event["candidate"]].time = event.get("time")
        elif event.get("type") == SandboxReady.type:
            run.sandbox = event.get("isolation")
        elif event.get("type") == ProposalReceived.type:
            proposal = event.get("proposal", {})
            run.tokens += proposal.get("prompt_tokens", 0) + proposal.get("completion_tokens", 0)
            run.cost_usd += proposal.get("cost_usd", 0.0)
    return run
