"""The graph walk of ``benchmarks/graph_memory.py`` counts what a fitted step keeps: the step's
own 33 or 42 numbers a particle, the known Hencky stress's SVD factors, and for the elastic task's
compiled law nothing more."""

from __future__ import annotations

import pytest
import torch

from tests.benchmarks.scripts import load_benchmark

graph_memory = load_benchmark("graph_memory")


def numbers(measured, node: str) -> float:
    return measured.by_node.get(node, 0.0) / measured.number_bytes


def test_a_step_keeps_its_state_and_the_laws_what_they_need(tmp_path):
    elastic = graph_memory.measure("elastic", 2, {"steps": "200"}, tmp_path)
    plastic = graph_memory.measure("plasticine", 2, {"steps": "200"}, tmp_path)
    # the step: input state (x, v, C, F_trial: 24) and F; the stress is the elastic law's
    # compiled output (9 more) or, for plasticine, F_corrected and the stress (18 more)
    assert numbers(elastic, "_MPMStepBackward") == 33
    # the compiled law keeps its input (the step's F) and its parameters (a few numbers)
    assert elastic.total / elastic.number_bytes == pytest.approx(33, abs=0.1)
    assert numbers(plastic, "_MPMStepBackward") == 42
    assert numbers(plastic, "_HenckyStressBackward") == 21  # U, s, V of F_corrected
    assert plastic.total > elastic.total and plastic.particles == 2000
    assert elastic.segments_at_once <= 5 and plastic.segments_at_once <= 5  # batch_particles


def test_every_storage_counts_once_under_the_first_node_that_keeps_it():
    x = torch.ones(10, requires_grad=True)
    y = x.exp()  # keeps its result
    z = (y * y).sum()  # keeps y twice: the same storage
    kept = graph_memory.kept_by_node(z.grad_fn)
    assert sum(kept.values()) == 10 * x.element_size()


def test_an_option_without_a_value_is_refused():
    with pytest.raises(SystemExit, match="KEY=VALUE"):
        graph_memory.main(["--tasks", "elastic", "--option", "law_kernels"])
