"""The soak benchmark's bookkeeping (``benchmarks/soak.py``): which processes it samples, and
the figures it prints from its samples. The soak itself runs outside CI."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.benchmarks.scripts import load_benchmark

soak = load_benchmark("soak")


def recorder(samples, finished=()) -> object:
    record = soak.Recorder()
    record.samples = list(samples)
    record.finished = list(finished)
    return record


def test_a_slot_s_fit_workers_count_as_one_helper_the_larger_while_both_run():
    samples = [
        (10.0, 50, "fit-a", 1, 500.0, 1400.0), (10.0, 50, "capture-a", 2, 340.0, 900.0),
        (20.0, 90, "fit-a", 1, 590.0, 1500.0), (20.0, 90, "fit-a", 3, 300.0, 1200.0),
        (30.0, 120, "fit-a", 3, 505.0, 1410.0), (30.0, 120, "capture-a", 2, 340.0, 900.0),
    ]  # fmt: skip
    figures = soak.reference_and_end(recorder(samples, finished=[1.0] * 120))
    assert figures == {"fit-a": (500.0, 505.0, 590.0), "capture-a": (340.0, 340.0, 340.0)}


def test_rates_are_evaluations_per_minute_of_each_hundred():
    finished = [0.6 * (i + 1) for i in range(200)]  # 100 a minute, then the same
    assert soak.rates(finished) == [(100, pytest.approx(100.0)), (200, pytest.approx(100.0))]
    slower = finished + [finished[-1] + 1.2 * (i + 1) for i in range(100)]
    assert soak.window_rate(slower, first=True) == pytest.approx(100.0)
    assert soak.window_rate(slower, first=False) == pytest.approx(50.0)


def test_it_samples_only_its_own_helpers(tmp_path: Path):
    folder = tmp_path / "sga-sandbox-slot1"
    folder.mkdir()
    code = "import time; time.sleep(30)"
    helper = subprocess.Popen([sys.executable, "-c", code, "-m", "sga_agent.fit_worker"],
                              cwd=folder)  # fmt: skip
    try:
        deadline = time.monotonic() + 10  # a loaded machine may show the child late
        found = {}
        while not found and time.monotonic() < deadline:
            found = {name: pid for name, pid, _, _ in soak.helpers(os.getpid())}
            time.sleep(0.05)
    finally:
        helper.kill()
        helper.wait()
    assert found == {"fit-slot1": helper.pid}
