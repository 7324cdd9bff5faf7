"""A run folder read back into plain records (no task imports, no simulator)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sga_agent.causes import cause_of
from sga_agent.config import current_format
from sga_agent.events import (
    CandidateEvaluated,
    CandidateScreened,
    ProposalReceived,
    SandboxReady,
)
from sga_agent.heap import ranked_loss
from sga_agent.run_store import CONFIG, SCREEN, SUMMARY, RunStore


@dataclass
class Answer:
    """What the proposer's answer left beside the code (a run from before these records has
    only the temperature, or nothing)."""

    temperature: float | None = None
    finish_reason: str = ""  # "stop", "length" (cut off), ...; "" when unknown
    parents: list[str] = field(default_factory=list)  # the candidates its prompt showed
    analysis: str = ""
    plan: str = ""
    reasoning: str = ""  # the provider's own reasoning, apart from the answer


@dataclass
class Screen:
    """A candidate's screen in a multi-fidelity search: its short fit (``screen.json``), whose
    loss compares only with other screens'."""

    status: str
    loss: float
    repeat: bool = False  # a copy of an earlier screen of the same code (counted once)
    time: float | None = None  # when it was recorded (seconds since the epoch)


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
    cause: str = ""  # why it failed, in one line (:func:`~sga_agent.causes.cause_of`)
    answer: Answer | None = None  # None for the seed and other candidates no proposer wrote
    screen_only: bool = False  # screened but never fitted fully: its status is the screen's
    screen: Screen | None = None  # its screen, in a multi-fidelity search

    def artifacts(self) -> dict[str, Any]:
        """What the trusted fit left for reports (read when asked: it can be large)."""
        return _read_json(self.folder / "artifacts.json", {}) if self.folder else {}

    @property
    def iteration(self) -> int:
        """The search iteration, from the id's prefix (``00-seed`` is iteration 0)."""
        return int(self.id.split("-", 1)[0])

    @property
    def repeat(self) -> bool:
        """Whether its code repeats an earlier candidate's (the end screen does not count it)."""
        return "duplicate_of" in self.extras

    @property
    def promoted(self) -> bool:
        """Whether it was screened, then fitted in full."""
        return self.screen is not None and not self.screen_only


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
    screened: list[Candidate] = field(default_factory=list)  # screens never fitted fully

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

    def every_candidate(self) -> list[Candidate]:
        """The evaluated candidates and those only screened, by iteration, then id."""
        every = [*self.candidates, *self.screened]
        return sorted(every, key=lambda candidate: (candidate.iteration, candidate.id))

    def screens(self) -> list[Candidate]:
        """The screened candidates (none outside a multi-fidelity search), by iteration, then
        id; each holds its :class:`Screen`."""
        return [candidate for candidate in self.every_candidate() if candidate.screen is not None]


def _read_json(path: Path, default: Any) -> Any:
    return json.loads(path.read_text(encoding="utf-8")) if path.is_file() else default


def _read_text(path: Path) -> str:
    return path.read_text(encoding="utf-8") if path.is_file() else ""


def read_answer(folder: Path) -> Answer | None:
    """What a proposer recorded of its answer in ``folder`` (None when it recorded nothing)."""
    proposal = _read_json(folder / "proposal.json", None)
    if proposal is None:
        return None
    temperature = proposal.get("temperature")
    return Answer(
        temperature=float(temperature) if isinstance(temperature, int | float) else None,
        finish_reason=str(proposal.get("finish_reason") or ""),
        parents=[str(parent) for parent in proposal.get("parents") or []],
        analysis=_read_text(folder / "analysis.md"),
        plan=_read_text(folder / "plan.md"),
        reasoning=_read_text(folder / "reasoning.md"),
    )


def read_screen(folder: Path) -> Screen | None:
    """The screen recorded in ``folder`` (``screen.json``), or None when it has none."""
    screen = _read_json(folder / SCREEN, None)
    if screen is None:
        return None
    return Screen(
        status=screen.get("status", "ok" if screen.get("valid") else "invalid"),
        loss=float(screen.get("loss", math.inf)),
        repeat="duplicate_of" in (screen.get("extras") or {}),
    )


def _candidate(folder: Path, evaluation: dict[str, Any], screen_only: bool = False) -> Candidate:
    return Candidate(
        id=folder.name,
        status=evaluation.get("status", "ok" if evaluation.get("valid") else "invalid"),
        loss=float(evaluation.get("loss", math.inf)),
        reason=evaluation.get("reason", ""),
        parameters=evaluation.get("parameters", {}),
        extras=evaluation.get("extras", {}),
        code=_read_text(folder / "code.py"),
        feedback=_read_text(folder / "feedback.txt") or str(evaluation.get("feedback", "")),
        curves=_read_json(folder / "curves.json", {}),
        folder=folder,
        cause=cause_of(evaluation),
        answer=read_answer(folder),
        screen_only=screen_only,
        screen=read_screen(folder),
    )


def read_candidate(folder: Path) -> Candidate | None:
    """The candidate in ``folder``, or None while it has no ``evaluation.json`` yet."""
    evaluation = _read_json(folder / "evaluation.json", None)
    return None if evaluation is None else _candidate(folder, evaluation)


def read_screen_only(folder: Path) -> Candidate | None:
    """The candidate in ``folder`` as its screen left it, when it has a screen
    (``screen.json``) and no full evaluation; else None."""
    if (folder / "evaluation.json").is_file():
        return None
    screen = _read_json(folder / SCREEN, None)
    return None if screen is None else _candidate(folder, screen, screen_only=True)


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
        screened=[c for c in map(read_screen_only, folders) if c is not None],
    )
    by_id = {candidate.id: candidate for candidate in candidates}
    screens = {candidate.id: candidate.screen for candidate in run.screens()}
    for event in store.events():
        if run.started is None and isinstance(event.get("time"), int | float):
            run.started = float(event["time"])
        if event.get("type") == CandidateEvaluated.type and event.get("candidate") in by_id:
            by_id[event["candidate"]].time = event.get("time")
        elif event.get("type") == CandidateScreened.type and event.get("candidate") in screens:
            screens[event["candidate"]].time = event.get("time")
        elif event.get("type") == SandboxReady.type:
            run.sandbox = event.get("isolation")
        elif event.get("type") == ProposalReceived.type:
            proposal = event.get("proposal", {})
            run.tokens += proposal.get("prompt_tokens", 0) + proposal.get("completion_tokens", 0)
            run.cost_usd += proposal.get("cost_usd", 0.0)
    return run
