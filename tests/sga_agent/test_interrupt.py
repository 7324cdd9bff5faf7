"""Ctrl-C during `sga-agent search`: it stops within seconds, kills its workers, records
nothing unfinished, and `sga-agent resume` evaluates only what had not finished.

The search runs a task installed through a real entry point (a ``dist-info`` folder on
``PYTHONPATH``) whose evaluations of a ``held`` solution wait while a file exists, so the
signal always finds one evaluation running and one finished.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.plugins import register_task

TASK_MODULE = '''
"""A task whose evaluations of "held" solutions wait while the file ``hold`` exists."""

import ast
import time
from pathlib import Path

from sga_agent.task import Evaluation, PromptParts

HOLD = Path(__file__).with_name("hold")


def answer(smiles):
    return "```python\\nSMILES = " + repr(smiles) + "\\ncoordinates = [[0.0, 0.0, 0.0]]\\n```"


class HeldProposer:
    name = "builtin:held"

    def propose_from(self, parents, temperature, n, seed):
        kind = "held" if temperature > 0.75 else "quick"
        return [answer(f"{kind}-{seed}-{i}") for i in range(n)]


class HeldTask:
    name = "held"
    description = "Evaluations of held solutions wait while a file exists (a test double)."
    kind = "entity"

    def seed_solution(self):
        return "SMILES = 'seed'\\ncoordinates = [[0.0, 0.0, 0.0]]\\n"

    def prompt_parts(self):
        return PromptParts(role="tester", context="", template="", requirements="")

    def builtin_proposer(self):
        return HeldProposer()

    def capture(self, solution):
        return {"smiles": ast.literal_eval(solution.split("=", 1)[1].split("\\n", 1)[0].strip())}

    def evaluate(self, data, settings):
        if data["smiles"].startswith("held"):
            while HOLD.exists():
                time.sleep(0.05)
        return Evaluation(valid=True, loss=float(len(data["smiles"])), feedback="evaluated")
'''


@pytest.fixture
def held_task(tmp_path):
    """The ``held`` task on an entry point, its hold file, and the search's environment."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "held_task.py").write_text(TASK_MODULE)
    hold = site / "hold"
    hold.touch()
    temporary = tmp_path / "tmp"  # the sandbox's folders: a helper left running shows here
    temporary.mkdir()
    env = {**register_task(site, "held", "held_task:HeldTask"), "TMPDIR": str(temporary)}
    return hold, temporary, env


def start_search(out: Path, env: dict[str, str]) -> subprocess.Popen:
    command = [sys.executable, "-m", "sga_agent", "search", "--task", "held", "--model",
               "builtin", "--iterations", "2", "--exploit", "1", "--explore", "2",
               "--workers", "1", "--out-dir", str(out)]  # fmt: skip
    return subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
        start_new_session=True,
    )  # fmt: skip


def evaluations(run: Path) -> list[str]:
    """The candidates of every recorded evaluation event, in order (repeats included)."""
    found = []
    for line in (run / "events.jsonl").read_text().splitlines():
        try:
            event = json.loads(line)
        except json.JSONDecodeError:
            continue
        if event.get("type") == "evaluation":
            found.append(event["candidate"])
    return found


def wait_for_quick_candidate(out: Path, process: subprocess.Popen) -> Path:
    """The run folder, once iteration 1's quick candidate is recorded (the held one runs)."""
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline:
        runs = list(out.glob("*/events.jsonl"))
        if runs and "01-exploit-00" in evaluations(runs[0].parent):
            return runs[0].parent
        assert process.poll() is None, process.communicate()[1][-3000:]
        time.sleep(0.05)
    raise AssertionError("iteration 1's quick candidate was never recorded")


def helpers_left(temporary: Path) -> list[int]:
    """Processes still working in a sandbox folder of this test."""
    left = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                cwd = os.readlink(entry / "cwd")
            except OSError:
                continue
            if cwd.startswith(str(temporary)):
                left.append(int(entry.name))
    return left


def stop(process: subprocess.Popen, signals: int) -> tuple[float, str]:
    """Send SIGINT ``signals`` times; the seconds until the search exited, and its stderr."""
    start = time.monotonic()
    for _ in range(signals):
        process.send_signal(signal.SIGINT)
        time.sleep(0.05)
    _, stderr = process.communicate(timeout=60)
    return time.monotonic() - start, stderr


@pytest.mark.slow
def test_one_interrupt_stops_the_search_and_resume_finishes_only_the_rest(tmp_path, held_task):
    hold, temporary, env = held_task
    process = start_search(tmp_path / "runs", env)
    run = wait_for_quick_candidate(tmp_path / "runs", process)
    seconds, stderr = stop(process, signals=1)

    assert seconds < 10, f"the search took {seconds:.1f} s to stop"
    assert helpers_left(temporary) == []
    assert process.returncode == 130, stderr[-3000:]
    assert f"sga-agent resume {run}" in stderr
    assert "Traceback" not in stderr
    before = evaluations(run)
    assert "01-explore-00" not in before  # the held candidate was stopped, not recorded
    assert not (run / "summary.json").exists()

    hold.unlink()
    resumed = subprocess.run(
        [sys.executable, "-m", "sga_agent", "resume", str(run), "--json"],
        capture_output=True, text=True, timeout=300, env=env,
    )  # fmt: skip
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    after = evaluations(run)
    assert after[: len(before)] == before
    again = after[len(before) :]
    assert "01-explore-00" in again and not set(again) & set(before)
    assert sorted(after) == sorted(set(after))  # nothing evaluated twice
    assert json.loads(resumed.stdout.strip().splitlines()[-1])["evaluations"] == 7

    again = subprocess.run(
        [sys.executable, "-m", "sga_agent", "resume", str(run), "--json"],
        capture_output=True, text=True, timeout=300, env=env,
    )  # fmt: skip
    assert again.returncode == 0 and "this run had finished" in again.stderr
    assert evaluations(run) == after  # nothing evaluated again


@pytest.mark.slow
def test_a_second_interrupt_exits_at_once(tmp_path, held_task):
    _, temporary, env = held_task
    process = start_search(tmp_path / "runs", env)
    wait_for_quick_candidate(tmp_path / "runs", process)
    seconds, stderr = stop(process, signals=2)
    assert seconds < 5, f"the search took {seconds:.1f} s to stop"
    assert helpers_left(temporary) == []
    # 130 from the handler, or killed by SIGINT itself when the second one lands while the
    # interpreter is already exiting (its handlers are reset then): the shell shows 130 both ways
    assert process.returncode in (130, -signal.SIGINT), stderr[-3000:]


@pytest.mark.slow
def test_the_time_budget_stops_a_held_evaluation_and_a_resume_with_more_time_runs_it(
    tmp_path, held_task
):
    """The budget passes while two held evaluations wait (one running, one queued): the search
    ends near it, kills its helpers, records neither and names them; a resume with a larger
    --time-budget, recorded as the run's, evaluates them."""
    hold, temporary, env = held_task
    command = [sys.executable, "-m", "sga_agent", "search", "--task", "held", "--model",
               "builtin", "--iterations", "2", "--exploit", "1", "--explore", "2",
               "--workers", "1", "--time-budget", "6s", "--out-dir", str(tmp_path / "runs"),
               "--json"]  # fmt: skip
    started = time.monotonic()
    done = subprocess.run(command, capture_output=True, text=True, timeout=90, env=env)
    seconds = time.monotonic() - started
    assert done.returncode == 0, done.stderr[-3000:]
    assert seconds < 60, f"the search took {seconds:.1f} s"
    assert helpers_left(temporary) == []
    summary = json.loads(done.stdout.strip().splitlines()[-1])
    assert summary["stopped"] == "max_seconds=6.0 reached"
    assert summary["interrupted"] == ["01-explore-00", "01-explore-01"]
    (run,) = (tmp_path / "runs").iterdir()
    assert evaluations(run) == ["00-seed", "01-exploit-00"]

    hold.unlink()
    resumed = subprocess.run(
        [sys.executable, "-m", "sga_agent", "resume", str(run), "--time-budget", "5m", "--json"],
        capture_output=True, text=True, timeout=300, env=env,
    )  # fmt: skip
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert {"01-explore-00", "01-explore-01"} <= set(evaluations(run))
    assert json.loads((run / "config.json").read_text())["config"]["budgets"]["max_seconds"] == 300
