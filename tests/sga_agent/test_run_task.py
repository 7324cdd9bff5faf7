"""A search process resolves its task once, and a run folder written before the config had its
components (commit e69b748) is replayed and resumed to the same outcomes.

The task is ``number-a`` (:mod:`tests.benchmarks.doubles`, a fraction of a second a
candidate), registered by a dist-info on the path as a plugin would be, and evaluated in the
real sandbox; the registry's loads are counted in this process (the sandbox's helper processes
load it in theirs).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from sga_agent import registry
from sga_agent.cli import main
from tests.plugins import register_task

#: Written by e69b748's ``sga-agent search --task number-a --model builtin --iterations 2
#: --exploit 1 --explore 2 --top-k 2 --workers 1 --seed 0`` (its config.json flat).
OLD_RUN = Path(__file__).resolve().parent / "data" / "e69b748-number-a-run"
SETTINGS = ["--iterations", "2", "--exploit", "1", "--explore", "2", "--top-k", "2",
            "--workers", "1", "--seed", "0"]  # fmt: skip


@pytest.fixture
def loads(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """``number-a`` registered here and for the sandbox's processes; every task this process
    resolves through the registry, in order."""
    site = tmp_path / "site"
    env = register_task(site, "number-a", "tests.benchmarks.doubles:NumberTaskA")
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setenv("PYTHONPATH", env["PYTHONPATH"])
    resolved: list[str] = []
    load, resolve = registry.load_task, registry.resolve_task

    def counted(real):
        def wrapper(name: str):
            resolved.append(name)
            return real(name)

        return wrapper

    monkeypatch.setattr(registry, "load_task", counted(load))
    monkeypatch.setattr(registry, "resolve_task", counted(resolve))
    return resolved


def recorded(events: list[dict]) -> dict[str, tuple[str, float]]:
    """Each candidate's recorded status and loss."""
    return {
        event["candidate"]: (event["evaluation"]["status"], float(event["evaluation"]["loss"]))
        for event in events
        if event.get("type") == "evaluation"
    }


def events_of(run: Path) -> list[dict]:
    return [json.loads(line) for line in (run / "events.jsonl").read_text().splitlines()]


@pytest.mark.parametrize("source", [["--model", "builtin"], ["--replay", str(OLD_RUN)]])
def test_a_search_resolves_its_task_once(tmp_path, loads, source):
    out = tmp_path / "runs"
    result = CliRunner().invoke(main, ["search", "--task", "number-a", *source, *SETTINGS,
                                       "--out-dir", str(out), "--json"])  # fmt: skip
    assert result.exit_code == 0, result.output
    assert loads == ["number-a"]
    (run,) = out.iterdir()
    assert json.loads((run / "config.json").read_text())["config"]["loop"]["explore"] == 2
    # the built-in proposer is seeded as e69b748's was; the replay asks the recorded answers
    assert recorded(events_of(run)) == recorded(events_of(OLD_RUN))


def test_a_run_written_before_the_components_resumes_to_the_same_outcomes(tmp_path, loads):
    """Killed (here: cut) after iteration 1, e69b748's run is resumed by this version: its
    flat config is read, iteration 2's recorded answers are evaluated, nothing else."""
    run = tmp_path / "old-run"
    run.mkdir()
    shutil.copy(OLD_RUN / "config.json", run / "config.json")
    everything = events_of(OLD_RUN)
    cut = next(i for i, e in enumerate(everything) if e.get("candidate") == "02-exploit-00"
               and e["type"] == "evaluation")  # fmt: skip
    (run / "events.jsonl").write_text("".join(json.dumps(e) + "\n" for e in everything[:cut]))
    result = CliRunner().invoke(main, ["resume", str(run), "--json"])
    assert result.exit_code == 0, result.output
    assert loads == ["number-a"]
    events = events_of(run)
    resumed = recorded(events[cut:])
    assert sorted(resumed) == ["02-exploit-00", "02-explore-00", "02-explore-01"]
    assert recorded(events) == recorded(everything)
    assert not any(e["type"] == "proposal" for e in events[cut:])  # asked nothing again
    last = [e for e in everything if e["type"] == "iteration_done"][-1]
    assert json.loads(result.stdout)["best"] == last["top"][0]
