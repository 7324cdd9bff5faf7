"""The observed task's gradient holds what ``graph_memory_mb`` allows: segments shortened to fit
it, measured on the law at hand, and a law that cannot fit it refused with the options to change.
The small observation of the other tests; real captures and fits."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bridges.rollout import Rollout, State, step_graph_bytes
from sga_agent.task import EvaluationSettings
from tasks.constitutive.law_capture import capture_law
from tasks.constitutive.law_graph import build_law
from tasks.constitutive.prompt_text import ELASTIC_SEED
from tasks.observed.evaluation import (
    ALLOCATOR_SLACK,
    evaluate,
    gradient_segment,
    rollout_for,
    setup,
)
from tasks.observed.options import ObservedOptions
from tests.tasks.observed.conftest import observation_arrays


@pytest.fixture
def observation(tmp_path: Path) -> str:
    path = tmp_path / "observed.npz"
    np.savez(path, **observation_arrays(frames=6))
    return str(path)


def _rollout(options: ObservedOptions) -> Rollout:
    data, dtype = setup(options)
    return rollout_for(build_law(capture_law(ELASTIC_SEED), dtype), data.scene, options, dtype)


def test_segments_are_shortened_to_fit_the_budget(observation: str) -> None:
    roomy = ObservedOptions(observation, "elastic", segment=4)
    assert gradient_segment(_rollout(roomy), roomy) == 4
    rollout = _rollout(roomy)
    state = State.initial(rollout.scene, rollout.dtype)
    per_step, per_state = step_graph_bytes(rollout, state), sum(t.nbytes for t in state.tensors())
    two = ALLOCATOR_SLACK * (2 * per_step + 3 * per_state)  # 6 steps in segments of 2
    tight = ObservedOptions(observation, "elastic", segment=4, graph_memory_mb=two / 2**20)
    assert 2 <= gradient_segment(_rollout(tight), tight) < 4


def test_a_law_the_budget_cannot_hold_is_refused_with_the_options_to_change(
    observation: str,
) -> None:
    law = {"law": capture_law(ELASTIC_SEED)}
    options = ObservedOptions(observation, "elastic", graph_memory_mb=0.001)
    found = evaluate(law, EvaluationSettings(epochs=1, options=options))
    assert not found.valid and found.status == "out_of_memory"
    assert "MiB at least" in found.reason and "more than the budget of" in found.reason
    assert "--option graph_memory_mb=MiB" in found.reason and "--option frames=N" in found.reason
    roomy = ObservedOptions(observation, "elastic")
    fitted = evaluate(law, EvaluationSettings(epochs=1, options=roomy))
    assert fitted.valid and fitted.status == "ok"
