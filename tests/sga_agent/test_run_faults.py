"""Faults of the run folder (issue 31): a power cut mid-line, two writers, a full disk.

The search runs with the doubles of test_search (a scripted proposer, losses written in the
code), so each test takes well under a second; the disk-full test mounts a small tmpfs and is
skipped where this process may not mount one.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from sga_agent.cli import main
from sga_agent.run_store import EVENTS, RunFolderFull, RunStore
from sga_agent.search import Search
from tests.sga_agent.test_search import LAW, FakeTask, LossInCode, Scripted, config, run

ANSWERS = [LAW.format(value=v) for v in (5.0, 3.0, 7.0, 1.0, 2.0, 4.0)]


def ranking(result) -> list[tuple[str, float]]:
    return [(entry.candidate, entry.loss) for entry in result.heap.top(10)]


def evaluated(store: RunStore) -> list[str]:
    return [event["candidate"] for event in store.events() if event["type"] == "evaluation"]


def resume(store: RunStore, evaluator: LossInCode | None = None):
    """Continue ``store``'s run; the proposer answers only what the run has not recorded."""
    asked = len(store.recorded().proposals)
    search = Search(config(), FakeTask(), Scripted(ANSWERS[asked:]), evaluator or LossInCode(),
                    store)  # fmt: skip
    return search.run()


def test_a_power_cut_in_the_last_line_loses_only_that_evaluation(tmp_path):
    """The log is cut in the middle of an evaluation's line, as a power cut leaves it: the
    resume keeps every finished evaluation and runs the cut one again, once."""
    full, full_store, *_ = run(tmp_path / "full", ANSWERS)
    cut = full_store.path / EVENTS
    lines = cut.read_bytes().splitlines(keepends=True)
    evaluations = [i for i, line in enumerate(lines) if b'"type": "evaluation"' in line]
    last = lines[evaluations[5]]  # the sixth evaluation, the second of iteration 2
    cut.write_bytes(b"".join(lines[: evaluations[5]]) + last[: len(last) // 2])
    store = RunStore.open(full_store.path)
    kept = evaluated(store)
    assert len(kept) == 5
    evaluator = LossInCode()
    resumed = resume(store, evaluator)
    assert ranking(resumed) == ranking(full)
    assert len(evaluator.calls) == 2  # the cut evaluation and the one never started
    assert sorted(evaluated(store)) == sorted(set(evaluated(store)))  # each recorded once
    assert evaluated(store)[:5] == kept


@pytest.fixture
def holder(tmp_path):
    """A run folder, and a process that locks it as a running search or resume would."""
    store = RunStore.create(tmp_path, config(), {})
    store.unlock()  # this process created it; another one writes it now
    code = ("import sys, time\nfrom sga_agent.run_store import RunStore\n"
            "RunStore.open(sys.argv[1]).lock()\nprint('locked', flush=True)\ntime.sleep(60)\n")
    process = subprocess.Popen([sys.executable, "-c", code, str(store.path)],
                               stdout=subprocess.PIPE, text=True)  # fmt: skip
    assert process.stdout.readline().strip() == "locked"
    yield store, process
    process.kill()
    process.wait()


def test_a_second_resume_of_a_run_is_refused_naming_the_holder(holder):
    store, process = holder
    before = (store.path / EVENTS).read_bytes()
    result = CliRunner().invoke(main, ["resume", str(store.path)])
    assert result.exit_code == 1, result.output
    assert f"being written by another process (pid {process.pid})" in result.output
    assert (store.path / EVENTS).read_bytes() == before  # nothing interleaved
    process.send_signal(signal.SIGKILL)
    process.wait()
    RunStore.open(store.path).lock()  # released by the kernel when its holder died


def test_a_run_is_locked_by_the_process_that_creates_it(tmp_path):
    store = RunStore.create(tmp_path, config(), {})
    code = "import sys\nfrom sga_agent.run_store import RunStore\nRunStore.open(sys.argv[1]).lock()"
    done = subprocess.run([sys.executable, "-c", code, str(store.path)], capture_output=True,
                          text=True)  # fmt: skip
    assert done.returncode != 0 and f"(pid {os.getpid()})" in done.stderr
    store.lock()  # the creator may lock it again


@pytest.fixture
def small_disk(tmp_path):
    """A 1 MiB tmpfs, or a skip where this process cannot mount one."""
    mount = tmp_path / "disk"
    mount.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mount)],
                          capture_output=True, text=True)  # fmt: skip
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.strip() or done.returncode}")
    yield mount
    subprocess.run(["umount", "-l", str(mount)], check=False)


def fill(disk: Path, leave: int) -> Path:
    """Fill ``disk`` but ``leave`` bytes (rounded to pages); the filler's path."""
    filler = disk / "filler"
    with open(filler, "wb", buffering=0) as out:
        try:
            while True:
                out.write(b"\0" * 4096)
        except OSError:
            pass
    os.truncate(filler, max(filler.stat().st_size - leave, 0))
    return filler


def test_a_full_disk_stops_the_search_readably_and_it_resumes_with_space(tmp_path, small_disk):
    full, *_ = run(tmp_path / "full", ANSWERS)
    store = RunStore.create(small_disk, config(), {})
    filler = fill(small_disk, leave=24 * 1024)
    with pytest.raises(RunFolderFull) as stopped:
        Search(config(), FakeTask(), Scripted(ANSWERS), LossInCode(), store).run()
    message = str(stopped.value)
    assert "disk is full" in message and f"sga-agent resume {store.path}" in message
    for line in (store.path / EVENTS).read_text().splitlines()[:-1]:
        json.loads(line)  # every line but a cut last one is a whole event
    kept = evaluated(store)
    assert 0 < len(kept) < 7, kept
    filler.unlink()  # space is back
    resumed = resume(store)
    assert ranking(resumed) == ranking(full)
    assert sorted(evaluated(store)) == sorted(set(evaluated(store))) and len(evaluated(store)) == 7
    assert store.recorded().finished
