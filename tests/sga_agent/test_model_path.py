"""`sga-agent search --model` end to end against the stand-in provider, answering as real
models answer (the corpus), with the failures providers really have: a rate limit, a cut-off
answer, then silence mid-run; `sga-agent resume` once it answers again; the report."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import pytest

from sga_agent.proposers.litellm_backbone import PING_TOKENS
from sga_agent.standin import CorpusScript, Reply, ScriptedOpenAIServer, load_corpus
from tests.sga_agent.test_end_to_end import environment

#: Answers of iteration 1, by corpus file: a clean one, a reasoning model's (its reasoning
#: sent apart), a missing import, the class in the second of three blocks, an exact repeat,
#: an `if` on a tensor (the model's own error), and a cut-off answer asked again.
CHOSEN = (
    "01-gpt-4o-clean.md", "07-deepseek-r1-clean.md", "11-mistral-missing-import.md",
    "16-claude-class-not-last.md", "39-gpt-4o-exact-repeat.md", "28-gpt-4o-tensor-branch.md",
    "29-gpt-4o-truncated.md",
)  # fmt: skip


class Provider:
    """A stand-in provider: "ready" to the one-word request, a rate limit on the first
    request of iteration 1, the chosen answers (elastic ones after them) to the next
    ``answered`` requests (iteration 1: its two batches and the cut-off answer asked again),
    then silence until ``speak`` is called."""

    def __init__(self, answered: int = 3) -> None:
        corpus = {answer.file: answer for answer in load_corpus()}
        chosen = [corpus[name] for name in CHOSEN]
        rest = [a for a in corpus.values() if a.task == "elastic" and a.expect == "evaluated"]
        self.script = CorpusScript(chosen + [a for a in rest if a not in chosen])
        self.left: int | None = answered
        self.limited = False
        self.lock = threading.Lock()

    def speak(self) -> None:
        """Answer again, every choice with the first answer: the same code, evaluated once."""
        self.script = CorpusScript(self.script.answers["elastic"][:1])
        self.left = None

    def __call__(self, body: dict[str, Any]) -> Reply:
        if body.get("max_tokens") == PING_TOKENS:
            return Reply("ready")
        with self.lock:
            if not self.limited:
                self.limited = True
                return Reply.error(429, "Rate limit reached for requests")
            if self.left is not None:
                if self.left == 0:
                    return Reply.hang()
                self.left -= 1
        return self.script(body)


def command(out: Path, url: str) -> list[str]:
    return [
        sys.executable, "-m", "sga_agent", "search", "--task", "elastic", "--model",
        "openai/standin", "--api-base", url, "--iterations", "2", "--exploit", "1", "--explore",
        "6", "--top-k", "3", "--epochs", "1", "--option", "steps=20", "--workers", "2",
        "--timeout", "300", "--request-timeout", "3", "--retries", "1", "--out-dir", str(out),
    ]  # fmt: skip


@pytest.mark.slow
def test_a_search_with_a_model_that_falls_silent_stops_then_resumes(tmp_path):
    provider = Provider()
    with ScriptedOpenAIServer(provider) as server:
        run = subprocess.run(
            command(tmp_path, server.url), capture_output=True, text=True, timeout=900,
            env=environment(),
        )  # fmt: skip
        (folder,) = [path.parent for path in tmp_path.glob("*/events.jsonl")]

        # silent mid-run: stopped, not 0, the model and the cause named, the answers kept
        assert run.returncode == 1, run.stderr[-3000:]
        assert "gave up on openai/standin after 2 attempts" in run.stderr
        assert "did not answer within 3 s" in run.stderr
        assert f"sga-agent resume {folder}" in run.stderr
        assert not (folder / "summary.json").exists()
        candidates = folder / "candidates"
        statuses = {
            path.name: json.loads((path / "evaluation.json").read_text())
            for path in sorted(candidates.iterdir())
            if (path / "evaluation.json").is_file()
        }
        iteration_1 = {name: e for name, e in statuses.items() if name.startswith("01-")}
        assert len(iteration_1) == 7
        ok = [name for name, e in iteration_1.items() if e["status"] == "ok"]
        assert len(ok) >= 5  # clean, reasoning, missing import, class not last, cut-off re-asked
        duplicates = [e for e in iteration_1.values() if e["extras"].get("duplicate_of")]
        assert len(duplicates) == 1  # the exact repeat, evaluated once
        (branch,) = [e for e in iteration_1.values() if e["status"] == "invalid"]
        assert "At line 42 (`if J < 1:`)" in branch["reason"]  # the line, the cause, the fix
        assert "torch.where" in branch["reason"]
        fixed = [e["extras"]["read_as"] for e in iteration_1.values() if "read_as" in e["extras"]]
        assert any("import torch.nn as nn" in " ".join(fixes) for fixes in fixed)
        assert any("code blocks" in " ".join(fixes) for fixes in fixed)
        reasoning = [p for p in candidates.glob("01-*/reasoning.md")]
        assert reasoning and all((p.parent / "plan.md").is_file() for p in reasoning)
        proposals = [json.loads(p.read_text()) for p in candidates.glob("01-*/proposal.json")]
        assert sum(p["truncated_before"] for p in proposals) == 1
        assert {p["finish_reason"] for p in proposals} == {"stop"}

        # the provider answers again: the run resumes and finishes
        provider.speak()
        resumed = subprocess.run(
            [sys.executable, "-m", "sga_agent", "resume", str(folder), "--json"],
            capture_output=True, text=True, timeout=900, env=environment(),
        )  # fmt: skip
        assert resumed.returncode == 0, resumed.stderr[-3000:]
        summary = json.loads(resumed.stdout.strip().splitlines()[-1])
        assert summary["causes"]  # the top causes of failure, for machines
        prompt = json.loads((candidates / "02-exploit-00" / "messages.json").read_text())
        failures = prompt[-1]["content"].split("## What went wrong in the last iteration")[1]
        assert "if J < 1:" in failures and "torch.where" in failures  # it reaches the model
        assert "the same code as" in failures  # and so does the repeat

    report = subprocess.run(
        [sys.executable, "-m", "sga_agent", "report", str(folder), "--no-motion"],
        capture_output=True, text=True, timeout=600, env=environment(),
    )  # fmt: skip
    assert report.returncode == 0, report.stderr[-3000:]
    html = (folder / "report" / "report.html").read_text()
    assert "Candidates" in html and "01-explore-05" in html and "reasoning" in html
