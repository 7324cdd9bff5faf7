"""Run events: each type is spelled in sga_agent.events, and the log format stays as it was."""

from __future__ import annotations

import json
import re
from pathlib import Path

from sga_agent import events
from sga_agent.config import SearchConfig
from sga_agent.run_store import RunStore

SGA_AGENT = Path(__file__).resolve().parents[2] / "sga_agent"
#: Modules another change owns; their event strings are left as they are for now.
EXEMPT = {"events.py"}
#: ``"type": "x"``, ``event["type"] == "x"``, ``event.get("type") == "x"``.
SPELLED = re.compile(r"""["']type["'][)\]]?\s*(?::|==|!=)\s*["'](\w+)""")


def test_events_are_written_as_runs_always_wrote_them(tmp_path):
    config = SearchConfig(task="elastic", proposer="builtin")
    store = RunStore.create(tmp_path, config, {"proposer": "builtin"})
    store.append(events.RunResumed())
    store.append(events.RunResumed("10.0.0.1:6379"))
    store.append(events.SandboxReady({"network": "none"}, {"executor": "local", "workers": 2}))
    store.append(events.ProposerFailed("no key", transient=False))
    store.append(events.IterationDone(1, [{"candidate": "00-seed"}]))
    written = [{k: v for k, v in e.items() if k != "time"} for e in store.events()]
    assert written == [
        {"type": "run_started", "proposer": "builtin"},
        {"type": "resumed"},
        {"type": "resumed", "ray_address": "10.0.0.1:6379"},
        {"type": "sandbox", "isolation": {"network": "none"}, "executor": "local", "workers": 2},
        {"type": "proposer_error", "error": "no key", "transient": False},
        {"type": "iteration_done", "iteration": 1, "top": [{"candidate": "00-seed"}]},
    ]


def test_recorded_runs_are_read_back_through_the_event_types(tmp_path):
    """A log written by hand, as an older version wrote it, resumes."""
    store = RunStore.create(tmp_path, SearchConfig(task="elastic", proposer="builtin"), {})
    lines = [
        {"type": "proposal", "candidate": "01-exploit-00", "proposal": {"text": "x"}},
        {"type": "evaluation", "candidate": "00-seed",
         "evaluation": {"valid": True, "loss": 1.0, "feedback": "f"}},
        {"type": "run_finished", "stopped": ""},
    ]  # fmt: skip
    with open(store.path / "events.jsonl", "a") as log:
        log.writelines(json.dumps(line) + "\n" for line in lines)
    recorded = store.recorded()
    assert recorded.proposals == {"01-exploit-00": {"text": "x"}}
    assert recorded.evaluations["00-seed"].loss == 1.0 and recorded.finished


def test_event_types_are_unique_and_spelled_only_in_the_events_module():
    classes = [
        c for c in vars(events).values() if isinstance(c, type) and issubclass(c, events.Event)
    ]
    kinds = [c.type for c in classes if issubclass(c, events.Event) and c is not events.Event]
    assert len(kinds) == len(set(kinds)) >= 10
    for path in SGA_AGENT.rglob("*.py"):
        if str(path.relative_to(SGA_AGENT)) not in EXEMPT:
            spelled = SPELLED.findall(path.read_text(encoding="utf-8"))
            assert not spelled, f"{path.name} spells event types {spelled}; use sga_agent.events"
