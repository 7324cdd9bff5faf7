"""The run folder: an append-only event log plus one readable folder per candidate.

Layout of ``runs/<id>/``::

    config.json            the resolved SearchConfig (SearchConfig.to_dict; a run written
                           before its components has a flat one, read all the same)
    events.jsonl           one JSON object per line, flushed and fsynced per event
    candidates/<id>/       messages.json (the prompt, when the proposer read it),
                           response.txt, proposal.json, code.py, evaluation.json,
                           feedback.txt, curves.json, artifacts.json (what the trusted fit
                           left: the captured data, the best trajectory); screen.json, the
                           screen of a multi-fidelity search (a candidate that was not
                           promoted to the full fit has no evaluation.json)
    heap/iteration-NN.json the top of the heap after each iteration
    provenance.json        what the run is measured against (the task's ``provenance``: an
                           observation's hash, the truth it read), written when its first
                           search starts (a run from before this record: when it is
                           resumed) and never rewritten
    summary.json           written when the run ends (the search's totals), completed by
                           the runner with what the run found (``findings``)
    run.lock               locked (``fcntl.flock``) by the one process that writes the run,
                           for its lifetime; it holds that process's id

``events.jsonl`` is the source of truth: a run killed at any moment is resumed from it
(:meth:`RunStore.recorded`), and a finished evaluation is never lost because its event is on
disk before the next one starts. The folders are for people (and ``sga-agent report``).
A full disk stops the run with :class:`RunFolderFull`: what was written stays readable (a line
cut short is skipped when read back) and the run resumes once there is space again.
"""

from __future__ import annotations

import errno
import fcntl
import json
import math
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from sga_agent import events as ev
from sga_agent.config import SearchConfig, current_format
from sga_agent.task import Evaluation

CONFIG, EVENTS, SUMMARY, LOCK = "config.json", "events.jsonl", "summary.json", "run.lock"
PROVENANCE = "provenance.json"
#: The id of the task's seed solution, the first candidate of every run.
SEED = "00-seed"
#: A candidate's artifacts (what the trusted fit left for reports), beside its evaluation.
ARTIFACTS = "artifacts.json"
#: A candidate's screen in a multi-fidelity search (its cheaper evaluation), beside the full one.
SCREEN = "screen.json"


class RunStoreError(RuntimeError):
    """The run folder is missing, incomplete or from an incompatible version."""


class RunLocked(RunStoreError):
    """Another process is writing the run (a search or a resume of it)."""


class RunFolderFull(RunStoreError):
    """The run folder's disk is full (or its quota spent): the run stops, resumable."""


#: Lock files this process holds, by run folder: held until the process ends.
_HELD: dict[Path, IO[str]] = {}


@dataclass
class Recorded:
    """What a run folder already holds: model answers, full-fidelity evaluations and screens
    (a multi-fidelity search's cheaper evaluations), by candidate id, and the wall seconds its
    searches ran (each from its ``search_started``, plus the start-up before it, to its last
    event)."""

    proposals: dict[str, dict[str, Any]] = field(default_factory=dict)
    evaluations: dict[str, Evaluation] = field(default_factory=dict)
    screens: dict[str, Evaluation] = field(default_factory=dict)
    finished: bool = False
    stopped: str = ""  # the budget that stopped its last session, if one did
    seconds: float = 0.0


def _json_default(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    raise TypeError(f"not JSON-serialisable: {type(value).__name__}")


def _dump(path: Path, data: Any) -> None:
    _write(path, json.dumps(data, indent=2, default=_json_default) + "\n")


def _write(path: Path, text: str) -> None:
    with _space(path):
        path.write_text(text, encoding="utf-8")


@contextmanager
def _space(path: Path) -> Iterator[None]:
    """Turn a full disk while writing ``path`` into :class:`RunFolderFull`."""
    try:
        yield
    except OSError as error:
        if error.errno not in (errno.ENOSPC, errno.EDQUOT):
            raise
        run = next((folder for folder in path.parents if (folder / EVENTS).exists()), path.parent)
        raise RunFolderFull(
            f"the run folder's disk is full ({path.name} could not be written: "
            f"{error.strerror}); the search stopped and every finished evaluation is kept: free "
            f"some space, then `sga-agent resume {run}` continues the run"
        ) from error


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
        store.lock()
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

    def lock(self) -> None:
        """Become the one process that writes this run, until it ends (``fcntl.flock`` on
        ``run.lock``; the kernel releases it however the process ends). Raises
        :class:`RunLocked`, naming the holder's process id, when another process holds it."""
        key = self.path.resolve()
        if key in _HELD:
            return
        handle = open(self.path / LOCK, "a+", encoding="utf-8")  # noqa: SIM115 (kept open)
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            holder = handle.read().strip() or "unknown"
            handle.close()
            raise RunLocked(
                f"{self.path} is being written by another process (pid {holder}): a run is "
                "searched or resumed by one process at a time; wait for it to end, or stop it "
                f"(kill -INT {holder}) and resume then"
            ) from None
        try:
            handle.truncate(0)
            handle.write(f"{os.getpid()}\n")
            handle.flush()
        except OSError:
            pass  # a full disk: the lock holds all the same, without its pid
        _HELD[key] = handle

    def unlock(self) -> None:
        """Let another process write this run (a no-op unless this process holds it)."""
        handle = _HELD.pop(self.path.resolve(), None)
        if handle is not None:
            handle.close()

    def config_record(self) -> dict[str, Any]:
        """The run's config as recorded, in the current layout
        (:func:`~sga_agent.config.current_format`), its task options a dict: what can be read
        without the task (its name, the seed)."""
        data = json.loads((self.path / CONFIG).read_text(encoding="utf-8"))
        return current_format(data["config"])

    def update_config(self, config: SearchConfig) -> None:
        """Record ``config`` as the run's from now on (a resume that gave the run a new time
        budget), keeping config.json's other keys; written beside it and renamed over it, so
        a kill leaves the old or the new, never half of one."""
        data = json.loads((self.path / CONFIG).read_text(encoding="utf-8"))
        data["config"] = config.to_dict()
        written = self.path / f"{CONFIG}.new"
        _dump(written, data)
        os.replace(written, self.path / CONFIG)

    def config(self, options_type: type) -> SearchConfig:
        """The run's config, its task options built as an ``options_type`` object (the task's:
        load the task named by :meth:`config_record` once); raises
        :class:`~sga_agent.config.ConfigError` for settings this version refuses."""
        return SearchConfig.from_dict(self.config_record(), options_type)

    # ------------------------------------------------------------------ events

    def append(self, event: ev.Event | dict[str, Any]) -> None:
        """Append one event (an :class:`~sga_agent.events.Event` or its dict) durably (flushed
        and fsynced before returning).

        After a kill mid-write the log may end in a partial line: the event then starts on a
        line of its own, so the partial line alone is lost (and skipped when read back).
        """
        data = event.to_dict() if isinstance(event, ev.Event) else event
        line = json.dumps({"time": time.time(), **data}, default=_json_default)
        with _space(self.path / EVENTS), open(self.path / EVENTS, "a+b") as log:
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
        started = last = None  # the current search's first and latest event times
        for event in self.events():
            kind = event.get("type")
            moment = event.get("time")
            if kind == ev.SearchStarted.type:
                if started is not None and last is not None:
                    recorded.seconds += last - started
                started = moment
                recorded.seconds += event.get("start_up") or 0.0
            last = moment if isinstance(moment, (int, float)) else last
            if kind == ev.ProposalReceived.type:
                recorded.proposals[event["candidate"]] = event["proposal"]
            elif kind == ev.CandidateEvaluated.type:
                recorded.evaluations[event["candidate"]] = Evaluation.from_dict(event["evaluation"])
            elif kind == ev.CandidateScreened.type:
                recorded.screens[event["candidate"]] = Evaluation.from_dict(event["evaluation"])
            elif kind == ev.RunFinished.type:
                recorded.finished = True
                recorded.stopped = str(event.get("stopped") or "")
        if started is not None and last is not None:
            recorded.seconds += last - started
        return recorded

    # ------------------------------------------------------------------ artefacts

    def candidate_dir(self, candidate: str) -> Path:
        path = self.path / "candidates" / candidate
        with _space(path):
            path.mkdir(parents=True, exist_ok=True)
        return path

    def save_proposal(
        self, candidate: str, messages: list[dict[str, str]] | None, proposal: dict[str, Any]
    ) -> None:
        folder = self.candidate_dir(candidate)
        if messages is not None:
            _dump(folder / "messages.json", messages)
        _write(folder / "response.txt", proposal.get("text", ""))
        _dump(folder / "proposal.json", {k: v for k, v in proposal.items() if k != "text"})

    def save_answer_parts(self, candidate: str, parts: dict[str, str]) -> None:
        """The parts of a model's answer worth reading apart (its analysis, plan and
        reasoning), each ``<name>.md`` in the candidate's folder; empty ones are not written."""
        folder = self.candidate_dir(candidate)
        for name, text in parts.items():
            if text.strip():
                _write(folder / f"{name}.md", text.strip() + "\n")

    def save_evaluation(self, candidate: str, code: str | None, evaluation: Evaluation) -> None:
        folder = self.candidate_dir(candidate)
        if code is not None:
            _write(folder / "code.py", code)
        data = evaluation.to_dict()
        curves = data.pop("curves")
        artifacts = data.pop("artifacts")
        _dump(folder / "evaluation.json", data)
        _dump(folder / "curves.json", curves)
        if artifacts:
            _dump(folder / ARTIFACTS, artifacts)
        _write(folder / "feedback.txt", evaluation.feedback)

    def save_screen(self, candidate: str, code: str, evaluation: Evaluation) -> None:
        """A candidate's screen (its code, and ``screen.json``: the evaluation without its
        artifacts) beside its full evaluation, if it gets one."""
        folder = self.candidate_dir(candidate)
        _write(folder / "code.py", code)
        data = evaluation.to_dict()
        data.pop("artifacts")
        _dump(folder / SCREEN, data)

    def save_heap(self, iteration: int, top: list[dict[str, Any]]) -> None:
        folder = self.path / "heap"
        with _space(folder):
            folder.mkdir(exist_ok=True)
        _dump(folder / f"iteration-{iteration:02d}.json", top)

    def record_provenance(self, provenance: dict[str, Any]) -> None:
        """Write ``provenance.json`` unless the run has one (a resume keeps the first)."""
        if not (self.path / PROVENANCE).is_file():
            _dump(self.path / PROVENANCE, provenance)

    def provenance(self) -> dict[str, Any] | None:
        """What :meth:`record_provenance` wrote (None for a run that recorded none)."""
        path = self.path / PROVENANCE
        return json.loads(path.read_text(encoding="utf-8")) if path.is_file() else None

    def save_summary(self, summary: dict[str, Any]) -> None:
        _dump(self.path / SUMMARY, summary)

    def summary(self) -> dict[str, Any]:
        """What :meth:`save_summary` last wrote (empty before the run's end)."""
        path = self.path / SUMMARY
        return json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
