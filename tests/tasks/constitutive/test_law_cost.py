"""The cost check of captured laws (tasks.constitutive.law_cost): honest laws pass, costly
graphs are refused in well under a second with a reason the next prompt can use.

Honest laws are captured here (they are this project's own: the examples, the tasks' seeds
and ground-truth laws, the capture's warm-up law and laws of the GP proposer); the costly
graphs are written by hand as documents. The hostile corpus's costly laws, captured in a
confined process, are in tests/hostile/test_cost.py.
"""

from __future__ import annotations

import gc
import importlib.util
import json
import random
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from sga_agent.task import Parent
from tasks.constitutive import law_cost
from tasks.constitutive.gp import GeneticProgrammingProposer
from tasks.constitutive.gp.codegen import law_code
from tasks.constitutive.gp.genome import random_genome
from tasks.constitutive.law_capture import WARM_UP_LAW, capture_law
from tasks.constitutive.law_graph import LawGraph, LawGraphError, aten_operation, build_law
from tasks.constitutive.specs import SPECS

ROOT = Path(__file__).resolve().parents[3]
#: Longest a check may take, refusal or not (the issue asks for under a second).
SECONDS = 1.0


def _make_ground_truth():
    spec = importlib.util.spec_from_file_location("make_ground_truth",
                                                  ROOT / "scripts" / "make_ground_truth.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def honest_laws() -> dict[str, str]:
    """Every example law, every task's seed and ground-truth law (also 2x off), the warm-up."""
    truth = _make_ground_truth()
    laws = {path.name: path.read_text() for path in sorted((ROOT / "examples/laws").glob("*.py"))}
    for task, spec in SPECS.items():
        laws[f"{task} seed"] = spec.seed
        laws[f"{task} truth"] = truth.truth_code(task)
        laws[f"{task} truth 2x off"] = truth.truth_code(task, truth.TWICE_OFF[task])
    laws["capture warm-up law"] = WARM_UP_LAW
    return laws


def gp_laws(per_kind: int, seed: int) -> dict[str, str]:
    """Random GP laws and the GP proposer's answers at its exploit and explore temperatures."""
    rng = random.Random(seed)
    laws = {}
    for kind, task in (("elastic", "elastic"), ("plastic", "granular")):
        for index in range(per_kind):
            laws[f"random {kind} {index}"] = law_code(random_genome(rng, kind))
        proposer = GeneticProgrammingProposer(kind)
        parent = Parent(code=SPECS[task].seed, loss=1.0)
        for temperature in (0.5, 1.0):
            for index, answer in enumerate(proposer.propose_from([parent], temperature, 3, seed)):
                code = answer.split("```python\n", 1)[1].rsplit("```", 1)[0]
                laws[f"proposed {kind} T={temperature} {index}"] = code
    return laws


def cost_of(code: str) -> law_cost.LawCost:
    graph = LawGraph.from_json(json.loads(json.dumps(capture_law(code))))
    started = time.perf_counter()
    cost = law_cost.check_cost(graph, aten_operation)
    assert time.perf_counter() - started < SECONDS
    return cost


@pytest.mark.parametrize("name", list(honest_laws()))
def test_honest_laws_are_not_refused(name):
    cost = cost_of(honest_laws()[name])
    print(f"{name}: {law_cost.describe(cost)}")
    assert cost.per_particle <= law_cost.MAX_COST / 30  # the budget is far beyond them
    assert cost.fixed <= 100


def test_the_gp_proposers_laws_are_not_refused():
    for name, code in gp_laws(per_kind=6, seed=5).items():
        cost = cost_of(code)
        assert cost.per_particle <= law_cost.MAX_COST / 20, (name, law_cost.describe(cost))


@pytest.mark.heavy  # 27 s; test_the_gp_proposers_laws_are_not_refused, in CI, samples fewer
def test_many_gp_laws_are_not_refused():
    worst = max(cost_of(code).per_particle for code in gp_laws(per_kind=40, seed=8).values())
    print(f"the costliest of 80 random and 24 proposed GP laws: {worst:.0f} values per particle")
    assert worst <= law_cost.MAX_COST / 20


def test_a_law_selecting_by_a_mask_is_sized_at_its_largest():
    code = """
import torch
import torch.nn as nn


class Physics(nn.Module):
    def __init__(self, weight: float = 0.1):
        super().__init__()
        self.weight = nn.Parameter(torch.tensor(weight))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        G = F.clone()
        mask = G > 1.0
        G[mask] = G[mask] * self.weight
        return G + 0 * F[F.abs() > 0.5].sum()
"""
    cost = cost_of(code)
    assert 9 * 4 <= cost.per_particle <= 200  # every selection taken as 9 values per particle


# ------------------------------------------------------------------ costly graphs, by hand


def document(*nodes: tuple, output: int | None = None) -> dict:
    """A graph document of ``(op, args)`` or ``(op, args, kwargs)`` nodes; F is ``"F"``,
    node k is ``("n", k)``."""

    def encode(value):
        if value == "F":
            return {"input": 0}
        if isinstance(value, tuple) and value[0] == "n":
            return {"node": value[1]}
        if isinstance(value, list):
            return [encode(item) for item in value]
        return value

    return {
        "format": 1, "parameters": [], "constants": [],
        "nodes": [{"op": op, "args": encode(list(args)), "kwargs": rest[0] if rest else {}}
                  for op, args, *rest in nodes],
        "output": {"node": len(nodes) - 1 if output is None else output},
    }  # fmt: skip


HOG = document(
    ("aten.ones.default", [[1024, 1024, 256]], {"dtype": {"dtype": "float32"}}),
    ("aten.sum.default", [("n", 0)]),
    ("aten.mul.Tensor", [("n", 1), 0]),
    ("aten.add.Tensor", ["F", ("n", 2)]),
)
BATCH_SIZE = [("aten.sym_size.int", ["F", 0])]
COSTLY = {
    "a constant tensor of 1024 x 1024 x 256": (
        HOG, ["constant tensor of 268,435,456 elements", "(1024, 1024, 256)", "torch.ones"]),
    "a constant tensor of 1e8 elements": (
        document(("aten.full.default", [[100_000_000], 0.5]),
                 ("aten.mean.default", [("n", 0)]), ("aten.mul.Tensor", ["F", ("n", 1)])),
        ["constant tensor of 100,000,000 elements", "(100000000)", "torch.full"]),
    "an outer product of the batch, (B, B)": (
        document(*BATCH_SIZE, ("aten.view.default", ["F", [("n", 0), 9]]),
                 ("aten.t.default", [("n", 1)]), ("aten.mm.default", [("n", 1), ("n", 2)]),
                 ("aten.mean.dim", [("n", 3), [1]]), ("aten.view.default", [("n", 4), [-1, 1, 1]]),
                 ("aten.mul.Tensor", ["F", ("n", 5)])),
        ["shape (B, B)", "torch.mm", "grows faster than the number of particles"]),
    "a broadcast of the batch against itself, (B, 1, B)": (
        document(("aten.view.default", ["F", [-1]]), ("aten.view.default", ["F", [-1, 1, 1]]),
                 ("aten.mul.Tensor", [("n", 0), ("n", 1)]),
                 ("aten.sum.dim_IntList", [("n", 2), [2]]), ("aten.mul.Tensor", ["F", 1.0])),
        ["shape (9B, 1, 9B)", "torch.mul", "grows faster"]),
    "a graph without a device for its factory": (
        document(("aten.ones.default", [[1024, 1024, 256]]), ("aten.mul.Tensor", ["F", 1.0])),
        ["constant tensor of 268,435,456 elements"]),
    "a huge power of integers": (
        document(("operator.pow", [10, 100_000_000]), ("aten.mul.Tensor", ["F", ("n", 0)])),
        ["cannot be run on 1,000 particles"]),
    "a cube of the batch, (B, B, B)": (
        document(*BATCH_SIZE, ("aten.ones.default", [[("n", 0), ("n", 0), ("n", 0)]]),
                 ("aten.sum.default", [("n", 1)]), ("aten.mul.Tensor", ["F", ("n", 2)])),
        ["shape (B, B, B)", "grows faster"]),
    "16 M values per particle": (
        document(*BATCH_SIZE, ("aten.slice.Tensor", ["F", 1, 0, 1]),
                 ("aten.slice.Tensor", [("n", 1), 2, 0, 1]),
                 ("aten.expand.default", [("n", 2), [("n", 0), 4096, 4096]]),
                 ("aten.mean.dim", [("n", 3), [1, 2], True]), ("aten.mul.Tensor", ["F", ("n", 4)])),
        ["16,777,216 values per particle", "(B, 4096, 4096)", "torch.expand"]),
    "many large intermediates": (
        document(("aten.view.default", ["F", [-1, 3, 3, 1]]),
                 ("aten.expand.default", [("n", 0), [-1, 3, 3, 64]]),
                 *[("aten.mul.Tensor", [("n", 1 + k), 1.0]) for k in range(40)],
                 ("aten.sum.dim_IntList", [("n", 41), [3]])),
        ["intermediates hold about 23,", "values per particle at every step", "20,000 allowed"]),
    "constants that add up": (
        document(*[("aten.zeros.default", [[99_000]]) for _ in range(11)],
                 ("aten.mul.Tensor", ["F", 1.0])),
        ["do not scale with the particles hold 1,089,000 values together"]),
    "a split into pieces per particle": (
        document(("aten.view.default", ["F", [-1]]), ("aten.split.Tensor", [("n", 0), 1]),
                 ("aten.mul.Tensor", ["F", 1.0])),
        ["splits a tensor into 9,000 pieces"]),
}


def assert_refused_quickly(name: str, data: dict, words: list[str] | tuple[str, ...]) -> str:
    """``build_law`` refuses ``data`` in under a second with a reason holding ``words``."""
    started = time.perf_counter()
    with pytest.raises(LawGraphError) as refused:
        build_law(data, torch.float32)
    seconds = time.perf_counter() - started
    print(f"{name}: refused in {seconds * 1e3:.1f} ms: {refused.value}")
    assert seconds < SECONDS
    for word in words:
        assert word in str(refused.value)
    return str(refused.value)


@pytest.mark.parametrize("name", list(COSTLY))
def test_a_costly_graph_is_refused_in_under_a_second_with_a_reason(name):
    assert_refused_quickly(name, *COSTLY[name])


def test_a_graph_that_fails_on_other_batch_sizes_is_refused_with_the_hint():
    fixed = document(("aten.view.default", ["F", [1000, 9]]), ("aten.mul.Tensor", ["F", 1.0]))
    with pytest.raises(LawGraphError, match="cannot be run on 2,000 particles.*any number"):
        build_law(fixed, torch.float32)


def test_the_largest_honest_graph_is_checked_in_under_a_second():
    """MAX_NODES operations on (B, 3) tensors, within the budget: the check's worst case in
    time (on (B, 3, 3) tensors, so many operations cost more than the budget allows)."""
    from tasks.constitutive.law_graph import MAX_NODES

    nodes = [("aten.sum.dim_IntList", ["F", [2]])]
    nodes += [("aten.mul.Tensor", [("n", k), 1.0]) for k in range(MAX_NODES - 1)]
    graph = LawGraph.from_json(document(*nodes))
    # the check's own time, not the collector's pauses over the objects earlier tests left:
    # timed with collection on, the full suite once measured 1.08 s where it alone took 0.11
    gc.collect()
    gc.disable()
    try:
        started = time.perf_counter()
        cost = law_cost.check_cost(graph, aten_operation)
        seconds = time.perf_counter() - started
    finally:
        gc.enable()
    print(f"{MAX_NODES} operations checked in {seconds:.2f} s: {law_cost.describe(cost)}")
    assert cost.per_particle == 3 * MAX_NODES and seconds < SECONDS
    with pytest.raises(law_cost.CostRefused, match="about 36,000 values per particle"):
        law_cost.check_cost(LawGraph.from_json(document(
            *[("aten.mul.Tensor", ["F" if k == 0 else ("n", k - 1), 1.0]) for k in range(MAX_NODES)]
        )), aten_operation)  # fmt: skip


def test_sizing_honest_laws_loads_no_compiler_stack():
    """A fit worker never imports torch._dynamo (see tasks.constitutive.inner's Adam): the
    check sizes the common operations itself where ATen's meta kernels would import it."""
    documents = [capture_law(code) for code in honest_laws().values()]
    documents += [capture_law(code) for code in list(gp_laws(per_kind=4, seed=2).values())]
    script = (
        "import json, sys\n"
        "from tasks.constitutive.law_graph import LawGraph, aten_operation\n"
        "from tasks.constitutive.law_cost import check_cost\n"
        "before = set(sys.modules)\n"
        "for document in json.load(sys.stdin):\n"
        "    check_cost(LawGraph.from_json(document), aten_operation)\n"
        "print(json.dumps(sorted(m for m in set(sys.modules) - before\n"
        "                        if m.startswith(('torch._dynamo', 'sympy')))))\n"
    )
    done = subprocess.run([sys.executable, "-c", script], input=json.dumps(documents),
                          capture_output=True, text=True, check=True, cwd=ROOT)  # fmt: skip
    assert json.loads(done.stdout.splitlines()[-1]) == []
