"""The side-by-side epoch benchmark's options (``benchmarks/evaluate_speed.py``): which task
options each configuration of ours runs with. The benchmark itself runs outside CI."""

from __future__ import annotations

import argparse
import importlib.util
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location(
    "bench_evaluate_speed", REPO / "benchmarks" / "evaluate_speed.py"
)
evaluate_speed = importlib.util.module_from_spec(_spec)
sys.modules["bench_evaluate_speed"] = evaluate_speed
_spec.loader.exec_module(evaluate_speed)


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
