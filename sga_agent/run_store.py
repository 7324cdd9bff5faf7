"""The run folder: an append-only event log plus one readable folder per candidate.

Layout of ``runs/<id>/``::

    config.json            the resolved SearchConfig
    events.jsonl           one JSON object per line, flushed and fsynced per event
    candidates/<id>/       messages.json (the prompt, when the proposer read it),
                           response.txt, proposal.json, code.py, evaluation.json,
                           feedback.txt, curves.json, artifacts.json (what the trusted fit
                           left: the captured data, the best trajectory)
    heap/iteration-NN.json the top of the heap after each iteration
    summary.json           written when the run ends

``events.jsonl`` is the source of truth: a run killed at any moment is resumed from it
(:meth:`RunStore.recorded`), and a finished evaluation is never lost because its event is on
disk before the next one starts. The folders are for people (and ``sga-agent report``).
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sga_agent import events as ev
from sga_agent.config import SearchConfig
from sga_agent.task import Evaluation

CONFIG, EVENTS, SUMMARY = "config.json", "events.jsonl", "summary.json"
#: A candidate's artifacts (what the trusted fit left for reports), beside its evaluation.
ARTIFACTS = "artifacts.json"


class RunStoreError(RuntimeError):
    """The run folder is missing, incomplete or from an incompatible version."""


@dataclass
class Recorded:
    """What a run folder already holds: model answers and evaluations, by candidate id."""

    proposals: dict[str, dict[str, Any]] = field(default_factory=dict)
    evaluations: dict[str, Evaluation] = field(default_factory=dict)
    finished: bool = False


def _json_default(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    raise TypeError(f"not JSON-serialisable: {type(value).__name__}")


def _dump(path: Path, data: Any) -> None:
    path.write_text(json.dumps(data, indent=2, default=_json_default) + "\n", encoding="utf-8")


class RunStore:
    """Writes (and reads back) one run folder."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)

    # ------------------------------------------------------------------ creating, opening

    @classmethod
    def create(cls, parent: Path, config: SearchConfig, meta: dict[str, Any]) -> RunStore:
        """A new folder ``parent/<task>-<timestamp>`` with the config and a start event."""
        parent = Path(parent)
        stamp = time.strftime("%Y%m%d-%H%M%S")
        path = parent / f"{config.task}-{stamp}"
        suffix = 1
        while path.exists():
            suffix += 1
            path = parent / f"{config.task}-{stamp}-{suffix}"
        path.mkdir(parents=True)
        store = cls(path)
        _dump(path / CONFIG, {"config": config.to_dict(), **meta})
        store.append(ev.RunStarted(meta))
        return store

    @classmethod
    def open(cls, path: Path) -> RunStore:
        store = cls(Path(path))
        if not (store.path / CONFIG).is_file() or not (store.path / EVENTS).is_file():
            raise RunStoreError(
                f"{path} is not a run folder (it needs {CONFIG} and {EVENTS}); pass the folder "
                "that `sga-agent search` printed"
            )
        return store

    def config(self) -> SearchConfig:
        data = json.loads((self.path / CONFIG).read_text(encoding="utf-8"))
        return SearchConfig.from_dict(data["config"])

    # ------------------------------------------------------------------ events

    def append(self, event: ev.Event | dict[str, Any]) -> None:
        """Append one event (an :class:`~sga_agent.events.Event` or its dict) durably (flushed
        and fsynced before returning).

        After a kill mid-write the log may end in a partial line: the event then starts on a
        line of its own, so the partial line alone is lost (and skipped when read back).
        """
        data = event.to_dict() if isinstance(event, ev.Event) else event
        line = json.dumps({"time": time.time(), **data}, default=_json_default)
        with open(self.path / EVENTS, "a+b") as log:
            if log.tell() > 0:
                log.seek(-1, os.SEEK_END)
                if log.read(1) != b"\n":
                    line = "\n" + line
            log.write((line + "\n").encode("utf-8"))
            log.flush()
            os.fsync(log.fileno())

    def events(self) -> list[dict[str, Any]]:
        """Every complete event (a line cut short by a kill is ignored)."""
        events = []
        with open(self.path / EVENTS, encoding="utf-8") as log:
            for line in log:
                try:
                    events.append(json.loads(line))
                except json.JSONDecodeError:
                    continue  # the last line of a killed run may be partial
        return events

    def recorded(self) -> Recorded:
        recorded = Recorded()
        for event in self.events():
            kind = event.get("type")
            if kind == ev.ProposalReceived.type:
                recorded.proposals[event["candidate"]] = event["proposal"]
            elif kind == ev.CandidateEvaluated.type:
                recorded.evaluations[event["candidate"]] = Evaluation.from_dict(event["evaluation"])
            elif kind == ev.RunFinished.type:
                recorded.finished = True
        return recorded

    # ------------------------------------------------------------------ artefacts

    def candidate_dir(self, candidate: str) -> Path:
        path = self.path / "candidates" / candidate
        path.mkdir(parents=True, exist_ok=True)
        return path

    def save_proposal(
        self, candidate: str, messages: list[dict[str, str]] | None, proposal: dict[str, Any]
    ) -> None:
        folder = self.candidate_dir(candidate)
        if messages is not None:
            _dump(folder / "messages.json", messages)
        (folder / "response.txt").write_text(proposal.get("text", ""), encoding="utf-8")
        _dump(folder / "proposal.json", {k: v for k, v in proposal.items() if k != "text"})

    def save_evaluation(self, candidate: str, code: str | None, evaluation: Evaluation) -> None:
        folder = self.candidate_dir(candidate)
        if code is not None:
            (folder / "code.py").write_text(code, encoding="utf-8")
        data = evaluation.to_dict()
        curves = data.pop("curves")
        artifacts = data.pop("artifacts")
        _dump(folder / "evaluation.json", data)
        _dump(folder / "curves.json", curves)
        if artifacts:
            _dump(folder / ARTIFACTS, artifacts)
        (folder / "feedback.txt").write_text(evaluation.feedback, encoding="utf-8")

    def save_heap(self, iteration: int, top: list[dict[str, Any]]) -> None:
        folder = self.path / "heap"
        folder.mkdir(exist_ok=True)
        _dump(folder / f"iteration-{iteration:02d}.json", top)

    def save_summary(self, summary: dict[str, Any]) -> None:
        _dump(self.path / SUMMARY, summary)
