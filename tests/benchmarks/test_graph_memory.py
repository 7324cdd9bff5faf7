"""The graph walk of ``benchmarks/graph_memory.py`` counts what a fitted step keeps: the step's
own 33 or 35 numbers a particle (the known Hencky stress's compact SVD among them, not the
stress), for the elastic task's compiled law nothing more, for the plastic one its input and
its SVD's values."""

from __future__ import annotations

import pytest
import torch

from tests.benchmarks.scripts import load_benchmark

graph_memory = load_benchmark("graph_memory")


def numbers(measured, node: str) -> float:
    return measured.by_node.get(node, 0.0) / measured.number_bytes


def test_a_step_keeps_its_state_and_the_laws_what_they_need(tmp_path):
    elastic = graph_memory.measure("elastic", 2, {"steps": "200"}, tmp_path)
    # the plastic law in torch (float64, this session's precision, leaves it there anyway)
    plastic = graph_memory.measure("plasticine", 2, {"steps": "200", "law_kernels": "none"},
                                   tmp_path)  # fmt: skip
    # the step: its input motion (x, v, C: 15) and F (9); the elastic law's compiled stress (9)
    assert numbers(elastic, "_MPMStepBackward") == 33
    # the compiled law keeps its input (the step's F) and its parameters (a few numbers)
    assert elastic.total / elastic.number_bytes == pytest.approx(33, abs=0.1)
    # plasticine: the motion, F_corrected and, for the Hencky stress computed again in the
    # step's reverse, F_corrected's SVD as quaternions and singular values (11), not the stress
    assert numbers(plastic, "_MPMStepBackward") == 35
    assert numbers(plastic, "_HenckyStressBackward") == 0  # F_corrected and its SVD: counted
    # the law's SVD and its U diag(s) Vh: the SVD's factors (21) and s (3), not the scaled U
    assert numbers(plastic, "_SVDBackward") + numbers(plastic, "_ScaledProductBackward") == 24
    assert plastic.total / plastic.number_bytes == pytest.approx(71, abs=0.1)  # and 12 others
    assert plastic.particles == 2000
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
