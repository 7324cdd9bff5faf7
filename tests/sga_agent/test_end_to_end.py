"""`sga-agent search` end to end: the real litellm client against a scripted local server,
a real constitutive task in sandboxed workers, then `sga-agent resume` of a killed run."""

from __future__ import annotations

import json
import os
import pty
import re
import select
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from sga_agent.standin import ScriptedOpenAIServer

KEY = "sk-test-not-a-real-key-0123456789"
LAWS = Path(__file__).resolve().parents[2] / "examples" / "laws"


def answer(code: str) -> str:
    plan = "### Analysis\nLooked at it.\n\n### Step-by-Step Plan\n1. Do it.\n\n"
    return f"{plan}### Code\n```python\n{code}```\n"


NEO_HOOKEAN = (LAWS / "neo_hookean.py").read_text()
SOFTER = NEO_HOOKEAN.replace("log_youngs_modulus: float = 13.0", "log_youngs_modulus: float = 12.0")
RAISES = """import torch
import torch.nn as nn


class Physics(nn.Module):
    def forward(self, F: torch.Tensor) -> torch.Tensor:
        return F @ F[:, :2]
"""
NAN = """import torch
import torch.nn as nn


class Physics(nn.Module):
    def forward(self, F: torch.Tensor) -> torch.Tensor:
        return F / (F - F)
"""
HOSTILE = """import os
import torch.nn as nn

os.system("touch /tmp/sga-hostile")


class Physics(nn.Module):
    def forward(self, F):
        open("/tmp/sga-hostile", "w").write("x")
        return F
"""
SCRIPT = [
    "ready",  # the one-word request a search sends before it starts
    [answer(NEO_HOOKEAN), answer(SOFTER)],  # exploit, n=2
    ["I would rather not write code.", answer(RAISES), answer(NAN), answer(HOSTILE)],  # explore
]
EXPECTED = {
    "00-seed": "ok",
    "01-exploit-00": "ok",
    "01-exploit-01": "ok",
    "01-explore-00": "invalid",
    "01-explore-01": "invalid",  # the shape mismatch stops its capture
    "01-explore-02": "unstable",
    "01-explore-03": "invalid",
}


def search_command(out: Path, *source: str) -> list[str]:
    """A tiny search of the elastic task; ``source`` names the model (or the replayed run)."""
    return [
        sys.executable, "-m", "sga_agent", "search", "--task", "elastic", *source,
        "--iterations", "1", "--exploit", "2", "--explore", "4", "--top-k", "3",
        "--epochs", "1", "--option", "steps=20", "--workers", "2", "--timeout", "300",
        "--out-dir", str(out), "--json",
    ]  # fmt: skip


def model(url: str) -> tuple[str, ...]:
    return ("--model", "openai/test-model", "--api-base", url)


def environment() -> dict[str, str]:
    return {**os.environ, "OPENAI_API_KEY": KEY}


@pytest.mark.slow
def test_search_end_to_end(tmp_path):
    with ScriptedOpenAIServer(SCRIPT) as server:
        run = subprocess.run(
            search_command(tmp_path, *model(server.url)),
            capture_output=True, text=True, timeout=900, env=environment(),
        )  # fmt: skip
        requests = server.requests
    assert run.returncode == 0, run.stderr[-3000:]
    summary = json.loads(run.stdout.strip().splitlines()[-1])
    folder = Path(summary["run"])
    assert [r["temperature"] for r in requests] == [0.0, 0.5, 1.0]
    assert [r.get("n") for r in requests] == [None, 2, 4]
    system, user = requests[1]["messages"]
    assert system["role"] == "system" and "### Code" in user["content"]

    statuses = {}
    for candidate in EXPECTED:
        evaluation = json.loads((folder / "candidates" / candidate / "evaluation.json").read_text())
        statuses[candidate] = evaluation["status"]
    assert statuses == EXPECTED
    # ranking: the true law, then the softer one, then the linear seed; invalid ones last
    ranked = [entry["candidate"] for entry in summary["top"]]
    assert ranked == ["01-exploit-00", "01-exploit-01", "00-seed"]
    assert not Path("/tmp/sga-hostile").exists()
    for candidate in EXPECTED:
        files = {p.name for p in (folder / "candidates" / candidate).iterdir()}
        assert {"code.py", "evaluation.json", "feedback.txt", "curves.json"} <= files
    for name in ("messages.json", "response.txt", "proposal.json"):
        assert (folder / "candidates" / "01-explore-03" / name).is_file()
    assert (folder / "heap" / "iteration-01.json").is_file()
    assert (folder / "config.json").is_file() and (folder / "summary.json").is_file()
    everything = "".join(p.read_text() for p in folder.rglob("*") if p.is_file())
    assert KEY not in everything and KEY not in run.stderr


def in_a_terminal(command: list[str], timeout_s: float) -> tuple[int, str]:
    """Run ``command`` on a pseudo-terminal, as a user would (rich's live progress bar on);
    its exit code and everything it wrote to the screen."""
    screen, terminal = pty.openpty()
    process = subprocess.Popen(command, stdin=terminal, stdout=terminal, stderr=terminal)
    os.close(terminal)
    written = []
    deadline = time.monotonic() + timeout_s
    try:
        while time.monotonic() < deadline:
            if select.select([screen], [], [], 1.0)[0]:
                try:
                    chunk = os.read(screen, 65536)
                except OSError:  # EIO: the command has closed the terminal
                    break
                if not chunk:
                    break
                written.append(chunk)
        return process.wait(timeout=max(1.0, deadline - time.monotonic())), b"".join(
            written
        ).decode("utf-8", "replace")
    finally:
        if process.poll() is None:
            process.kill()
        os.close(screen)


TAICHI_LOG_LINE = re.compile(r"\[Taichi\]|\[[TDIWEC] \d\d/\d\d/\d\d ")


@pytest.mark.slow
def test_the_end_of_a_searchs_screen_has_no_taichi_log_line(tmp_path):
    """The findings start Taichi in the search's own process under the progress bar (the true
    law's loss, the best law's free run): none of its log lines may reach the screen."""
    command = [
        sys.executable, "-m", "sga_agent", "search", "--task", "elastic", "--iterations", "1",
        "--exploit", "1", "--explore", "0", "--epochs", "1", "--option", "steps=100",
        "--workers", "1", "--out-dir", str(tmp_path),
    ]  # fmt: skip
    code, screen = in_a_terminal(command, timeout_s=600)
    assert code == 0, screen[-3000:]
    assert "free run of the best" in screen and "report: sga-agent report" in screen
    assert not TAICHI_LOG_LINE.search(screen), screen[-3000:]


def events_in(log: Path) -> list[dict]:
    """The events a run's log holds so far (a line being written is skipped)."""
    events = []
    for line in log.read_text().splitlines():
        try:
            events.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return events


def fitted_in_iteration_1(log: Path) -> int:
    """How many iteration-1 candidates the sandbox finished (rejections are stored at once)."""
    submitted = {"01-exploit-00", "01-exploit-01", "01-explore-01", "01-explore-02"}
    return sum(e.get("type") == "evaluation" and e.get("candidate") in submitted
               for e in events_in(log))  # fmt: skip


def screened_in_iteration_1(log: Path) -> int:
    """How many iteration-1 screens the sandbox finished."""
    return sum(event.get("type") == "screened" for event in events_in(log))


def killed_once(folder: Path, counted: Callable[[Path], int], *args: str) -> Path:
    """The events log of a search (``args`` added), SIGKILLed as soon as ``counted`` finds one
    thing in that log (within 10 minutes, else the test fails)."""
    with ScriptedOpenAIServer(SCRIPT) as server:
        process = subprocess.Popen(
            search_command(folder, *model(server.url), *args),
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=environment(),
            start_new_session=True,
        )  # fmt: skip
        events = None
        deadline = time.time() + 600
        while time.time() < deadline:
            logs = list(folder.glob("*/events.jsonl"))
            if logs and counted(logs[0]) >= 1:
                events = logs[0]
                break
            time.sleep(0.05)
        os.killpg(process.pid, signal.SIGKILL)
        process.wait()
    assert events is not None, "the search never got to iteration 1"
    return events


def resumed_and_replayed(folder: Path, replay_folder: Path, *args: str) -> tuple[dict, dict]:
    """The summaries of ``sga-agent resume`` of the killed run in ``folder`` and of a search
    replaying its answers (``args`` added)."""
    resumed = subprocess.run(
        [sys.executable, "-m", "sga_agent", "resume", str(folder), "--json"],
        capture_output=True, text=True, timeout=900, env=environment(),
    )  # fmt: skip
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    replay = subprocess.run(
        search_command(replay_folder, "--replay", str(folder), *args),
        capture_output=True, text=True, timeout=900, env=environment(),
    )  # fmt: skip
    assert replay.returncode == 0, replay.stderr[-3000:]
    after = json.loads(resumed.stdout.strip().splitlines()[-1])
    return after, json.loads(replay.stdout.strip().splitlines()[-1])


@pytest.mark.heavy
def test_killed_search_resumes_to_the_same_heap(tmp_path):
    """kill -9 once the first evaluation of iteration 1 is stored, resume, compare with a
    replayed run. Each evaluation is stored as it finishes, so the others are still running."""
    events = killed_once(tmp_path / "killed", fitted_in_iteration_1)
    folder = events.parent
    assert not (folder / "summary.json").exists()
    assert fitted_in_iteration_1(events) < 4, "the kill came after every evaluation finished"

    after, replayed = resumed_and_replayed(folder, tmp_path / "replay")
    assert after["top"] == replayed["top"]
    assert after["evaluations"] == replayed["evaluations"] == 7


@pytest.mark.slow
def test_killed_multi_fidelity_search_resumes_to_the_same_heap(tmp_path):
    """--fidelity multi: kill -9 once the first screen is stored, resume, compare with a
    replayed run; the four laws that run are screened, the best valid screen's fitted in full."""
    multi = ("--fidelity", "multi", "--screen-fidelity", "0.5", "--promote", "0.25")
    events = killed_once(tmp_path / "killed", screened_in_iteration_1, *multi)
    folder = events.parent
    assert screened_in_iteration_1(events) < 4, "the kill came after every screen finished"
    loop = json.loads((folder / "config.json").read_text())["config"]["loop"]
    assert (loop["fidelity"], loop["screen_fidelity"], loop["promote"]) == ("multi", 0.5, 0.25)

    after, replayed = resumed_and_replayed(folder, tmp_path / "replay", *multi)
    assert after["top"] == replayed["top"]
    # only the promoted law and the seed were fitted in full (then the rejected, invalid)
    assert [entry["candidate"] for entry in after["top"]][:2] == ["01-exploit-00", "00-seed"]
    assert [entry["valid"] for entry in after["top"]] == [True, True, False]
    # the seed, two rejections, four screens and one full fit
    assert after["evaluations"] == replayed["evaluations"] == 8
    assert after["screened"] == replayed["screened"] == 4
