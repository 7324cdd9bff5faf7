"""The side-by-side epoch benchmark's options (``benchmarks/evaluate_speed.py``): which task
options each configuration of ours runs with, and its probe of a run's own memory. The
benchmark itself runs outside CI."""

from __future__ import annotations

import argparse
import time

import pytest

from tests.benchmarks.scripts import load_benchmark

evaluate_speed = load_benchmark("evaluate_speed")


def _args(**values) -> argparse.Namespace:
    return argparse.Namespace(**({"option": [], "graph_memory_mb": None} | values))


def test_options_come_from_option_flags_and_the_graph_budget_flag():
    args = _args(option=["law_kernels=svd-inputs", " steps = 200 "], graph_memory_mb=120.0)
    assert evaluate_speed.our_options(args) == {
        "law_kernels": "svd-inputs", "steps": "200", "graph_memory_mb": "120.0",
    }  # fmt: skip


def test_a_variant_adds_its_options_to_ours_under_its_label():
    runs = evaluate_speed.variants(
        ["small:graph_memory_mb=100,law_kernels=none", "plain:"], {"steps": "200"}
    )
    assert runs == {
        "small": (evaluate_speed.ROOT, {"steps": "200", "graph_memory_mb": "100",
                                        "law_kernels": "none"}),
        "plain": (evaluate_speed.ROOT, {"steps": "200"}),
    }  # fmt: skip


@pytest.mark.parametrize("text", ["ours:steps=200", "baseline:steps=1", ":steps=1", "x:steps"])
def test_a_variant_without_its_own_label_or_a_value_is_refused(text):
    with pytest.raises(SystemExit):
        evaluate_speed.variants([text], {})


@pytest.mark.skipif(evaluate_speed.anonymous_mb() is None, reason="needs /proc's smaps_rollup")
def test_the_own_memory_peak_sees_a_heap_allocation_that_is_freed_again():
    peak = evaluate_speed.AnonymousPeak(interval=0.01)
    peak.start()
    before = evaluate_speed.anonymous_mb()
    block = bytearray(100 * 2**20)  # 100 MiB of zeros, written: resident
    block[:: 4096] = b"\1" * len(block[:: 4096])
    deadline = time.monotonic() + 5
    while (peak.peak_mb or 0) < before + 90 and time.monotonic() < deadline:
        time.sleep(0.01)
    del block
    assert peak.stop() >= before + 90
    assert evaluate_speed.anonymous_mb() < before + 50  # freed: the peak kept it, not the process
