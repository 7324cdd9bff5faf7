"""Long runs and faults: a slot recycles its warm fit worker, and blames only the candidate.

A warm fit worker that is due (a number of evaluations, or its memory grown past a bound) is
replaced by a fresh one that warms up first, so that no candidate waits for it. A helper that
dies for a reason outside the candidate (a SIGKILL from outside, out of memory in a worker that
had evaluated before) gets its candidate's step tried once more on a fresh helper; what the
candidate itself does (a segfault, a limit) is its verdict. The double task is
:class:`tests.sga_agent.doubles.HealthTask`.
"""

from __future__ import annotations

import json
import os
import random
import signal
import threading
import time
from pathlib import Path

import pytest

from sga_agent.config import SearchConfig
from sga_agent.helper_protocol import FitSettings
from sga_agent.run_store import RunStore
from sga_agent.sandbox import EvaluationSlot, Recycling, SandboxLimits, SandboxPool
from sga_agent.search import Search
from sga_agent.task import EvaluationSettings
from tests.sga_agent import doubles
from tests.sga_agent.test_search import Scripted

REPO_ROOT = Path(__file__).resolve().parents[2]
TASK = "tests.sga_agent.doubles:HealthTask"
LIMITS = SandboxLimits(timeout_s=60)
SETTINGS = FitSettings.of(EvaluationSettings())  # as a pool sends them to its slots


def candidate(loss: float, **report) -> str:
    return f"loss = {loss}\nreport = {report!r}\n"


def slot(recycling: Recycling = Recycling()) -> EvaluationSlot:  # noqa: B008 (frozen)
    return EvaluationSlot(LIMITS, [REPO_ROOT], recycling=recycling)


def until_new_worker(evaluator: EvaluationSlot, first_pid: int, **report) -> list:
    """Evaluate candidates until one is fitted by another worker than ``first_pid``."""
    evaluations, deadline = [], time.monotonic() + 60
    while not evaluations or evaluations[-1].extras["fit_pid"] == first_pid:
        assert time.monotonic() < deadline, "the fit worker was never replaced"
        evaluations.append(evaluator.evaluate(TASK, candidate(1.0, **report), SETTINGS))
        assert evaluations[-1].valid, evaluations[-1].reason
        time.sleep(0.05)
    return evaluations


def gone(pid: int) -> bool:
    """Whether process ``pid`` has exited (a zombie counts: it runs nothing)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z"
    except OSError:
        return True


def test_a_worn_fit_worker_is_replaced_by_a_warm_one():
    evaluator = slot(Recycling(evaluations=3, growth=None))
    try:
        evaluations = until_new_worker(evaluator, first_pid=-1)
        first_pid = evaluations[0].extras["fit_pid"]
        evaluations += until_new_worker(evaluator, first_pid)
        time.sleep(0.5)
        evaluator.evaluate(TASK, candidate(1.0), SETTINGS)  # reaps the retired worker
    finally:
        evaluator.close()
    old = [e for e in evaluations if e.extras["fit_pid"] == first_pid]
    new = evaluations[len(old)]
    assert len(old) >= 3
    assert new.extras["earlier"] == 0
    assert new.extras["warm_stages"] == 3  # warmed up before its first candidate
    assert gone(first_pid)


def test_a_fit_worker_whose_memory_grew_is_replaced():
    evaluator = slot(Recycling(evaluations=None, growth=1.3, reference=1))
    try:
        first = evaluator.evaluate(TASK, candidate(1.0, leak_mb=1), SETTINGS)
        evaluations = until_new_worker(evaluator, first.extras["fit_pid"], leak_mb=40)
    finally:
        evaluator.close()
    assert evaluations[-1].extras["earlier"] == 0
    assert evaluations[-1].extras["warm_stages"] == 3


def test_without_growth_or_wear_the_worker_stays():
    evaluator = slot(Recycling(evaluations=50, growth=2.0))
    try:
        pids = {evaluator.evaluate(TASK, candidate(1.0), SETTINGS).extras["fit_pid"]
                for _ in range(6)}  # fmt: skip
    finally:
        evaluator.close()
    assert len(pids) == 1


def test_recycling_is_validated():
    with pytest.raises(ValueError, match="growth must be above 1"):
        Recycling(growth=0.9)
    with pytest.raises(ValueError, match="evaluations must be at least 1"):
        Recycling(evaluations=0)


def _killed_while_fitting(evaluator: EvaluationSlot, release: Path, kills: int):
    """Evaluate a waiting candidate, SIGKILL the fit worker that fits it ``kills`` times
    (each time once it waits), then let it finish. (The evaluation runs in this thread: a
    helper dies with the thread that started it.)"""

    def kill() -> None:
        for _ in range(kills):
            deadline = time.monotonic() + 60
            while not (marks := list(release.parent.glob(f"{release.name}.fitting-*"))):
                if time.monotonic() > deadline:
                    return  # the fit never started: the evaluation says why
                time.sleep(0.02)
            pid = int(marks[0].name.rsplit("-", 1)[1])
            marks[0].unlink()
            os.kill(pid, signal.SIGKILL)
            while not gone(pid):
                time.sleep(0.02)
        release.write_text("")

    thread = threading.Thread(target=kill)
    thread.start()
    try:
        return evaluator.evaluate(TASK, candidate(0.5, wait=str(release)), SETTINGS)
    finally:
        thread.join()


def test_a_fit_worker_killed_from_outside_is_not_the_candidates_failure(tmp_path):
    evaluator = slot()
    try:
        evaluation = _killed_while_fitting(evaluator, tmp_path / "release", kills=1)
        after = evaluator.evaluate(TASK, candidate(2.0), SETTINGS)
    finally:
        evaluator.close()
    assert evaluation.valid and evaluation.loss == 0.5, evaluation.reason
    assert evaluation.extras["retried"] == "the fit worker was killed by SIGKILL"
    assert after.valid and "retried" not in after.extras


def test_a_candidate_whose_fit_dies_twice_gets_the_verdict(tmp_path):
    evaluator = slot()
    try:
        evaluation = _killed_while_fitting(evaluator, tmp_path / "release", kills=2)
    finally:
        evaluator.close()
    assert (evaluation.valid, evaluation.status) == (False, "crashed")
    assert evaluation.reason == "the fit worker failed: killed by SIGKILL"
    assert evaluation.extras["retried"] == "the fit worker was killed by SIGKILL"


def test_a_capture_server_killed_from_outside_is_not_the_candidates_failure():
    evaluator = slot()
    try:
        evaluator.evaluate(TASK, candidate(1.0), SETTINGS)  # the helpers are up
        server = evaluator._capture[1].process.pid
        threading.Timer(0.5, os.kill, (server, signal.SIGKILL)).start()
        evaluation = evaluator.evaluate(TASK, candidate(0.5, capture_sleep=1.5), SETTINGS)
    finally:
        evaluator.close()
    assert evaluation.valid and evaluation.loss == 0.5, evaluation.reason
    assert evaluation.extras["retried"] == "the capture server was killed by SIGKILL"


def test_a_capture_process_killed_by_sigkill_is_tried_once_more_then_judged():
    # not isolated: the confined capture is its PID namespace's init, which SIGKILL spares
    solution = "import os, signal\nos.kill(os.getpid(), signal.SIGKILL)\n"
    evaluator = EvaluationSlot(SandboxLimits(timeout_s=60, isolation=False), [REPO_ROOT])
    try:
        evaluation = evaluator.evaluate(TASK, solution, SETTINGS)
    finally:
        evaluator.close()
    assert (evaluation.valid, evaluation.status) == (False, "crashed")
    assert evaluation.reason.startswith("the capture process was killed by SIGKILL")
    assert evaluation.extras["retried"] == "the capture process was killed by SIGKILL"


@pytest.mark.parametrize(
    ("solution", "status"),
    [("import ctypes\nctypes.string_at(0)\n", "crashed"), ("import os\nos._exit(3)\n", "crashed"),
     ("while True:\n    pass\n", "timeout"), ("x = [0] * 2**40\n", "out_of_memory")],
)  # fmt: skip
def test_what_the_candidate_does_to_its_capture_is_judged_at_once(solution, status):
    limits = SandboxLimits(timeout_s=60, capture_timeout_s=2.0, memory_mb=512)
    evaluator = EvaluationSlot(limits, [REPO_ROOT])
    try:
        evaluation = evaluator.evaluate(TASK, solution, SETTINGS)
    finally:
        evaluator.close()
    assert (evaluation.valid, evaluation.status) == (False, status), evaluation.reason
    assert "retried" not in evaluation.extras


def test_out_of_memory_in_a_fresh_fit_worker_is_the_verdict():
    evaluator = slot()
    try:
        evaluation = evaluator.evaluate(TASK, candidate(1.0, oom="always"), SETTINGS)
    finally:
        evaluator.close()
    assert evaluation.status == "out_of_memory"
    assert "retried" not in evaluation.extras


def test_out_of_memory_in_a_worker_that_had_grown_is_tried_on_a_fresh_one():
    evaluator = slot()
    try:
        evaluator.evaluate(TASK, candidate(1.0), SETTINGS)
        grown = evaluator.evaluate(TASK, candidate(0.5, oom="grown"), SETTINGS)
        always = evaluator.evaluate(TASK, candidate(0.25, oom="always"), SETTINGS)
    finally:
        evaluator.close()
    assert grown.valid and grown.loss == 0.5 and grown.extras["earlier"] == 0
    assert grown.extras["retried"] == "the fit worker ran out of memory after 1 earlier evaluation"
    assert always.status == "out_of_memory"  # on the fresh worker too: the verdict
    assert always.extras["retried"].startswith("the fit worker ran out of memory")


# ---------------------------------------------------------------------- kill -9 in a search


def _answers(marks: Path) -> list[str]:
    code = [candidate(round(0.1 * i + 0.05, 2), sleep=0.2, capture_sleep=0.1, marks=str(marks))
            for i in range(24)]  # fmt: skip
    return [f"### Code\n```python\n{text}```\n" for text in code]


def _search(folder: Path, marks: Path, killer=None) -> RunStore:
    config = SearchConfig.from_settings(
        task=TASK, proposer="scripted", iterations=3, top_k=2, exploit=2, explore=6,
        workers=2, timeout_s=60.0, task_options=doubles.DoubleOptions(),
    )  # fmt: skip
    store = RunStore.create(folder, config, {})
    pool = SandboxPool(2, LIMITS, extra_python_path=[REPO_ROOT],
                       recycling=Recycling(evaluations=5))  # fmt: skip
    stop = threading.Event()
    thread = threading.Thread(target=killer, args=(store, stop)) if killer else None
    with pool:
        if thread:
            thread.start()
        try:
            Search(config, doubles.HealthTask(), Scripted(_answers(marks)), pool, store).run()
        finally:
            stop.set()
            if thread:
                thread.join()
    return store


def _busy_helpers(marks: Path) -> dict[int, str]:
    """This process's busy helpers by process id: capture servers capturing a candidate (they
    have a child then), fit workers fitting one (their mark is in ``marks``)."""
    parents, commands = {}, {}
    for entry in filter(str.isdigit, os.listdir("/proc")):
        try:
            stat = Path(f"/proc/{entry}/stat").read_text().rsplit(")", 1)[1].split()
            if stat[0] != "Z":
                parents[int(entry)] = int(stat[1])
            if int(stat[1]) == os.getpid():
                commands[int(entry)] = Path(f"/proc/{entry}/cmdline").read_bytes()
        except (OSError, ValueError, IndexError):
            continue
    fitting = {int(mark.name.rsplit("-", 1)[1]) for mark in marks.glob("fitting-*")}
    busy = {}
    for pid, command in commands.items():
        if b"sga_agent.capture_server" in command and pid in parents.values():
            busy[pid] = "capture"
        elif b"sga_agent.fit_worker" in command and pid in fitting and pid in parents:
            busy[pid] = "fit"
    return busy


def _retried(store: RunStore) -> int:
    return sum("retried" in e["evaluation"]["extras"] for e in store.events()
               if e["type"] == "evaluation")  # fmt: skip


def kill_busy_helpers(store: RunStore, stop: threading.Event, marks: Path,
                      kills: list[str]) -> None:  # fmt: skip
    """SIGKILL a random busy helper, again and again: each time once the previous kill's
    candidate has been recorded (as retried), or after 15 s (it hit an idle moment). A kind of
    helper not killed yet goes first (a capture is busy for a fraction of a second only)."""
    rng = random.Random(0)
    while not stop.wait(rng.uniform(0.1, 0.3)):
        busy = _busy_helpers(marks)
        if not busy:
            continue
        unkilled = {pid: kind for pid, kind in busy.items() if kind not in kills}
        pid = rng.choice(sorted(unkilled or busy))
        before = _retried(store)
        os.kill(pid, signal.SIGKILL)
        kills.append(busy[pid])
        deadline = time.monotonic() + 15
        while _retried(store) == before and time.monotonic() < deadline and not stop.is_set():
            time.sleep(0.05)


def _recorded(store: RunStore) -> dict[str, dict]:
    """Each candidate's recorded outcome, and how many times it was recorded."""
    outcomes: dict[str, dict] = {}
    for event in store.events():
        if event["type"] == "evaluation":
            evaluation = event["evaluation"]
            outcome = {key: evaluation[key] for key in ("valid", "loss", "status", "parameters")}
            previous = outcomes.setdefault(event["candidate"], {**outcome, "times": 0})
            previous["times"] += 1
    return outcomes


@pytest.mark.slow
def test_helpers_killed_during_a_search_lose_and_repeat_nothing(tmp_path):
    kills: list[str] = []
    quiet = _recorded(_search(tmp_path / "quiet", tmp_path))
    store = _search(tmp_path / "killed", tmp_path,
                    lambda s, stop: kill_busy_helpers(s, stop, tmp_path, kills))  # fmt: skip
    killed = _recorded(store)
    assert killed == quiet
    assert all(outcome["times"] == 1 for outcome in killed.values())
    assert len(killed) == 25 and all(outcome["valid"] for outcome in killed.values())
    assert {"capture", "fit"} <= set(kills), kills
    reasons = [json.dumps(e["evaluation"]["extras"].get("retried")) for e in store.events()
               if e["type"] == "evaluation"]  # fmt: skip
    assert any("the fit worker was killed by SIGKILL" in r for r in reasons), reasons
    assert any("the capture server was killed by SIGKILL" in r for r in reasons), reasons
