"""Plain lines of progress in a pipe (taichi_mpm/cli/heartbeat.py): when they come, what they
say, and that they come while Python's lock is held (as Taichi holds it to compile a kernel)."""

from __future__ import annotations

import io
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from taichi_mpm.cli import heartbeat
from taichi_mpm.cli.heartbeat import Heartbeat, Lines, clock

ROOT = Path(__file__).resolve().parents[2]


def test_nothing_in_the_grace_period_then_the_state_at_once():
    lines = Lines(now=100.0, grace_s=5.0, every_s=5.0, quiet_s=5.0)
    assert lines.state("compiling 1/16", 100.0) == []
    assert lines.tick(104.9) == []  # a command done by now printed what it always did
    assert lines.tick(105.0) == ["compiling 1/16 [0:00:05]"]
    assert lines.tick(106.0) == []


def test_a_change_waits_for_every_s_and_no_change_repeats_after_quiet_s():
    lines = Lines(now=0.0, grace_s=5.0, every_s=5.0, quiet_s=5.0)
    lines.state("compiling 1/16", 0.0)
    assert lines.tick(5.0) == ["compiling 1/16 [0:00:05]"]
    assert lines.state("compiling 2/16", 6.0) == []  # at most one line each 5 s
    assert lines.state("compiling 3/16", 7.0) == []
    assert lines.tick(10.0) == ["compiling 3/16 [0:00:10]"]  # the latest state
    assert lines.tick(14.9) == []
    assert lines.tick(15.0) == ["compiling 3/16 [0:00:15]"]  # unchanged: said again
    for now in range(16, 60):  # never silent for more than quiet_s while it works
        assert lines.tick(float(now)) == ([] if now % 5 else [f"compiling 3/16 [{clock(now)}]"])


def test_a_line_of_the_command_counts_as_a_line():
    lines = Lines(now=0.0, grace_s=5.0, every_s=5.0, quiet_s=5.0)
    lines.state("fitting", 0.0)
    lines.said(4.0)  # e.g. "Fitting yield_stress of vonmises ..."
    assert lines.tick(5.0) == [] and lines.tick(8.9) == []
    assert lines.tick(9.0) == ["fitting [0:00:09]"]


def test_a_stage_clock_counts_from_the_state_s_start():
    lines = Lines(now=0.0, grace_s=5.0, every_s=5.0, quiet_s=5.0, stage_clock=True)
    lines.state("still reading the run", 0.0)
    lines.state("still assessing the best solution", 3.0)
    assert lines.tick(5.0) == ["still assessing the best solution [0:00:02]"]
    assert lines.tick(10.0) == ["still assessing the best solution [0:00:07]"]


def test_no_state_no_line():
    lines = Lines(now=0.0)
    assert [line for now in range(30) for line in lines.tick(float(now))] == []


def test_in_memory_a_thread_prints_and_stops(monkeypatch):
    stream = io.StringIO()
    with Heartbeat(stream, grace_s=0.0, every_s=0.0, quiet_s=60.0) as beat:
        beat.state("first")
        beat.state("second  with\nspaces")  # one line, whatever it is given
        assert beat._child is None and beat._thread is not None
    assert stream.getvalue().splitlines() == ["first [0:00:00]", "second with spaces [0:00:00]"]
    beat.state("after the end")  # ignored
    assert stream.getvalue().count("\n") == 2


def test_an_inactive_heartbeat_prints_nothing():
    stream = io.StringIO()
    with Heartbeat(stream, grace_s=0.0, every_s=0.0, active=False) as beat:
        beat.state("on a terminal the live display says it")
    assert stream.getvalue() == ""


HOLDS_THE_LOCK = textwrap.dedent(
    """
    import re, sys, time
    from taichi_mpm.cli.heartbeat import Heartbeat

    with Heartbeat(grace_s=0.2, every_s=0.2, quiet_s=0.5) as beat:
        beat.state("holding the lock")
        started = time.monotonic()
        while time.monotonic() - started < 2.0:  # C code that keeps Python's lock (0.5 s)
            re.match(r"(a+)+$", "a" * 24 + "b")
        print("held", flush=True)
    print("stopped", flush=True)
    """
)


def test_in_a_pipe_a_child_process_prints_while_python_s_lock_is_held():
    """One real pipe, stdout and stderr merged: the lines come during the 2 s in which the
    process runs C code that never lets go of Python's lock (a thread could print none)."""
    done = subprocess.run(
        [sys.executable, "-c", HOLDS_THE_LOCK],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stdout
    lines = done.stdout.splitlines()
    assert lines[-1] == "stopped" and "held" in lines, done.stdout
    beats = lines[: lines.index("held")]
    assert len(beats) >= 2, done.stdout
    assert all(line.startswith("holding the lock [0:00:0") for line in beats), done.stdout


def test_stop_ends_the_child_at_once():
    beat = Heartbeat(sys.__stderr__, grace_s=60.0)
    beat.start()
    child = beat._child
    assert child is not None
    beat.state("nothing to print yet")
    started = time.monotonic()
    beat.stop()
    assert child.poll() is not None and time.monotonic() - started < 1.0


def test_the_report_s_copy_is_the_same_file():
    """sga_agent may not import taichi_mpm, nor taichi_mpm sga_agent: each keeps a copy."""
    mine = Path(heartbeat.__file__).read_text(encoding="utf-8")
    assert (ROOT / "sga_agent" / "report" / "heartbeat.py").read_text(encoding="utf-8") == mine


@pytest.mark.parametrize("seconds, shown", [(0, "0:00:00"), (65.9, "0:01:05"), (-1, "0:00:00")])
def test_clock(seconds, shown):
    assert clock(seconds) == shown
