"""SpareCores: the cores other processes leave free, from /proc/stat minus this process."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from taichi_mpm.spare_cores import SpareCores

HZ = os.sysconf("SC_CLK_TCK")


class FakeMachine:
    """A /proc/stat file, a clock and this process's CPU time, all set by the test."""

    def __init__(self, folder: Path) -> None:
        self.path = folder / "stat"
        self.now = 0.0
        self.own = 0.0
        self.ticks = {"user": 0, "nice": 0, "system": 0, "idle": 0}
        self.write()

    def write(self) -> None:
        t = self.ticks
        self.path.write_text(
            f"cpu  {t['user']} {t['nice']} {t['system']} {t['idle']} 0 0 0 0 0 0\n"
            "cpu0 0 0 0 0 0 0 0 0 0 0\n"
        )

    def advance(self, seconds: float, user: float = 0.0, nice: float = 0.0, own: float = 0.0):
        """``seconds`` pass; all processes use ``user`` core-seconds (``own`` of them ours) and
        low-priority ones ``nice``."""
        self.now += seconds
        self.own += own
        self.ticks["user"] += round(user * HZ)
        self.ticks["nice"] += round(nice * HZ)
        self.write()

    def monitor(self, cores: int = 2) -> SpareCores:
        return SpareCores(
            stat_path=self.path, clock=lambda: self.now, cores=cores, own_seconds=lambda: self.own
        )


def test_a_busy_core_of_another_process_is_not_free(tmp_path):
    machine = FakeMachine(tmp_path)
    spare = machine.monitor(cores=2)
    assert spare.free() == 2.0 and spare.allow(2)  # nothing measured yet: the machine is ours
    machine.advance(1.0, user=1.0)  # another process kept one core busy
    assert spare.free() == pytest.approx(1.0)
    assert spare.allow(1) and not spare.allow(2)


def test_our_own_threads_do_not_count_against_us(tmp_path):
    machine = FakeMachine(tmp_path)
    spare = machine.monitor(cores=2)
    machine.advance(1.0, user=2.0, own=2.0)  # both cores busy, all of it ours
    assert spare.free() == pytest.approx(2.0) and spare.allow(2)


def test_low_priority_work_yields_and_is_not_counted(tmp_path):
    machine = FakeMachine(tmp_path)
    spare = machine.monitor(cores=2)
    machine.advance(1.0, nice=1.0)
    assert spare.allow(2)


def test_readings_are_kept_for_an_interval_and_follow_the_load(tmp_path):
    machine = FakeMachine(tmp_path)
    spare = machine.monitor(cores=2)
    machine.advance(0.1, user=0.1)
    assert spare.free() == 2.0  # within the interval: no new reading
    machine.advance(0.9, user=0.9)
    assert spare.free() == pytest.approx(1.0)
    machine.advance(1.0)  # the other process ended
    assert spare.free() == pytest.approx(2.0)


def test_without_proc_stat_every_core_is_free(tmp_path):
    spare = SpareCores(stat_path=tmp_path / "missing", cores=4)
    assert spare.free() == 4.0 and spare.allow(4)


@pytest.mark.skipif(not Path("/proc/stat").exists(), reason="needs Linux's /proc/stat")
@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="needs two cores")
def test_a_real_spinning_process_takes_a_core():
    spinner = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        time.sleep(0.3)
        spare = SpareCores(interval=0.5)
        time.sleep(0.6)
        free = spare.free()
    finally:
        spinner.kill()
        spinner.wait()
    assert free <= spare.cores - 0.6
