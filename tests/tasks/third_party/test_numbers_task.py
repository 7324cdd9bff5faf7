"""The documented third-party plugin (``examples/numbers_plugin``: its own solution format, a
JSON list of numbers), registered through a real entry point of the ``sga_agent.tasks`` group
(a dist-info folder) and searched end to end (``sga-agent search --replay``: sandboxed capture
and fit processes included)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from sga_agent import registry
from sga_agent.config import SearchConfig
from sga_agent.events import ProposalReceived
from sga_agent.proposers.base import Proposal
from sga_agent.run_store import RunStore
from tests.plugins import REPO, register_task

PLUGIN = REPO / "examples" / "numbers_plugin"

#: The recorded answers the replay gives: (candidate, answer text).
ANSWERS = [
    ("01-exploit-00", "Closer:\n```\n[1, 2, 2.5]\n```\n"),
    ("01-explore-00", '```\n{"x": 1}\n```\n'),  # refused by the task's own check
    ("02-exploit-00", "```python\n[1.0, 2.0, 3.0]\n```\n"),
    ("02-explore-00", "```\n__import__('os')\n```\n"),  # refused by the generic rules
]


@pytest.fixture
def installed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> dict[str, str]:
    """The task registered by a dist-info on the path, here and for every process started
    with the returned environment (the CLI, its capture and fit workers)."""
    site = tmp_path / "site"
    env = register_task(site, "numbers", "sga_numbers:NumbersTask")
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.syspath_prepend(str(PLUGIN))  # the plugin's module, as pip would install it
    return {**env, "PYTHONPATH": os.pathsep.join([str(PLUGIN), env["PYTHONPATH"]])}


def recorded_run(parent: Path) -> Path:
    """A run folder holding a model's answers, as a search with a model would record them."""
    config = SearchConfig.from_settings(task="numbers", proposer="openai/gpt-4o", iterations=2,
                                        exploit=1, explore=1)  # fmt: skip
    store = RunStore.create(parent, config, {"proposer": "openai/gpt-4o"})
    for candidate, text in ANSWERS:
        proposal = Proposal(text, "openai/gpt-4o", 0.5, prompt_tokens=100, completion_tokens=20)
        store.append(ProposalReceived(candidate, proposal.to_dict()))
    return store.path


def test_the_registry_finds_the_task_through_its_entry_point(installed: dict[str, str]) -> None:
    assert "numbers" in registry.task_names()
    task = registry.load_task("numbers")
    assert task.kind == "entity" and task.seed_solution() == "[0, 0, 0]\n"


@pytest.mark.slow
def test_a_replayed_search_runs_the_third_party_task_end_to_end(
    tmp_path: Path, installed: dict[str, str]
) -> None:
    command = [
        sys.executable, "-m", "sga_agent", "search", "--task", "numbers",
        "--replay", str(recorded_run(tmp_path / "recorded")), "--iterations", "2",
        "--exploit", "1", "--explore", "1", "--top-k", "2", "--workers", "1",
        "--timeout", "60", "--out-dir", str(tmp_path / "runs"), "--json",
    ]  # fmt: skip
    run = subprocess.run(command, env=installed, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    summary = json.loads(run.stdout.strip().splitlines()[-1])
    assert summary["best"]["candidate"] == "02-exploit-00" and summary["best"]["loss"] == 0.0
    assert [entry["candidate"] for entry in summary["top"]] == ["02-exploit-00", "01-exploit-00"]
    assert (summary["valid"], summary["invalid"], summary["tokens"]) == (3, 2, 4 * 120)
    folder = Path(summary["run"])

    def evaluation(candidate: str) -> dict:
        return json.loads((folder / "candidates" / candidate / "evaluation.json").read_text())

    assert evaluation("00-seed")["loss"] == 14.0  # the seed went through capture and fit
    assert evaluation("01-exploit-00")["feedback"] == "squared distance 0.25"
    refused = evaluation("01-explore-00")["reason"]
    assert refused == (
        "the code was rejected before it ran: the solution must be a non-empty JSON list of "
        "finite numbers"
    )
    assert "'__import__' is not allowed" in evaluation("02-explore-00")["reason"]
