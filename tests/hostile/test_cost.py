"""The corpus's ``cost`` candidates, captured in a confined capture server, are refused by the
trusted side before any fit: from their graphs' sizes alone, in under a second, with a reason
the next prompt can use. One also goes through the task's whole ``evaluate``.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import asdict

import pytest

from sga_agent.registry import load_task
from sga_agent.sandbox import SandboxLimits, _LineProcess, worker_environment
from sga_agent.task import EvaluationSettings
from tasks.constitutive.options import ConstitutiveOptions
from tests.hostile.catalog import load_catalog
from tests.sga_agent.test_sandbox import ISOLATED
from tests.tasks.constitutive.test_law_cost import assert_refused_quickly

pytestmark = pytest.mark.skipif(not ISOLATED, reason="the capture cannot be isolated here")

COST = [candidate for candidate in load_catalog() if candidate.category == "cost"]
LIMITS = SandboxLimits(timeout_s=120, capture_timeout_s=60, memory_mb=2048)
#: What each refusal must say (the candidate's number: words of its reason).
REASONS = {
    "51": ("16,777,216 values per particle", "(B, 4096, 4096)"),
    "54": ("constant tensor of 1,600,000,000 elements", "(40000, 40000)"),
    "75": ("constant tensor of 268,435,456 elements", "(1024, 1024, 256)", "torch.ones"),
    "76": ("constant tensor of 100,000,000 elements", "(10000, 10000)", "torch.full"),
    "77": ("shape (B, B)", "torch.mm", "grows faster than the number of particles"),
    "78": ("shape (B, 1, B)", "torch.mul", "grows faster than the number of particles"),
}


@pytest.fixture(scope="module")
def captured(tmp_path_factory):
    """Each cost candidate's captured graph, from a confined capture server per task."""
    folder = tmp_path_factory.mktemp("capture")
    graphs = {}
    for task in sorted({candidate.task for candidate in COST}):
        command = [sys.executable, "-m", "sga_agent.capture_server", task]
        server = _LineProcess(command, worker_environment(LIMITS), folder, task)
        try:
            server.ask(None, 300)  # the ready line
            for candidate in [c for c in COST if c.task == task]:
                request = {"solution": candidate.code, "timeout_s": LIMITS.capture_timeout_s,
                           "limits": asdict(LIMITS), "isolation": None}  # fmt: skip
                answer = server.ask(request, LIMITS.timeout_s)
                assert answer["status"] == "ok", (candidate.name, answer)
                outcome = json.loads(answer["output"])
                assert "data" in outcome, (candidate.name, outcome)
                graphs[candidate.name] = outcome["data"]
        finally:
            server.close()
    return graphs


def test_every_cost_candidate_has_its_expected_reason():
    assert {candidate.name[:2] for candidate in COST} == set(REASONS)


@pytest.mark.parametrize("candidate", COST, ids=[c.name for c in COST])
def test_a_costly_law_is_refused_before_the_fit_in_under_a_second(candidate, captured):
    """The capture lets it through (its graph is small data); the trusted side does not."""
    graph = captured[candidate.name]["law"]
    reason = assert_refused_quickly(candidate.name, graph, REASONS[candidate.name[:2]])
    assert "keep every intermediate per particle" in reason


def test_the_task_evaluation_refuses_the_gigabyte_law_quickly(captured):
    """Through the fit's whole ``evaluate`` (Taichi started and all): invalid, with the reason
    as the feedback, in under 5 s."""
    [name] = [c.name for c in COST if c.name.startswith("75_")]
    task = load_task("granular")
    started = time.perf_counter()
    settings = EvaluationSettings(epochs=1, options=ConstitutiveOptions(steps=20))
    evaluation = task.evaluate(captured[name], settings)
    seconds = time.perf_counter() - started
    print(f"{name}: evaluate refused it in {seconds:.2f} s")
    assert seconds < 5.0
    assert evaluation.status == "invalid" and not evaluation.valid
    assert "268,435,456 elements" in evaluation.reason
