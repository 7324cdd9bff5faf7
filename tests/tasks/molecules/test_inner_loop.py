"""The inner loop moves the property towards the target while the strain stays bounded."""

from __future__ import annotations

import numpy as np
import pytest

from sga_agent.task import EvaluationSettings
from tasks.molecules import GapLowTask, HomoTask
from tasks.molecules.geometry import build_structure
from tasks.molecules.inner_loop import Objective, run_inner_loop
from tasks.molecules.solution import Proposal
from tasks.molecules.validation import check_proposal
from tests.tasks.molecules.helpers import conformer, score, solution_for

SMILES = "OCc1ccncc1F"  # 9 heavy atoms, 16 atoms in all: quick


@pytest.fixture(scope="module")
def structure():
    return build_structure(check_proposal(Proposal(SMILES, conformer(SMILES)[2].tolist())))


@pytest.mark.parametrize(
    ("prop", "target"), [("homo", 3.0), ("homo", -3.0), ("gap", -3.0), ("lumo", 3.0)]
)
def test_property_moves_towards_target_with_bounded_strain(structure, prop, target) -> None:
    trajectory = run_inner_loop(structure, Objective(prop, target), steps=8, learning_rate=0.01)
    assert len(trajectory.records) == 9 and not trajectory.stopped
    distance = np.abs(np.array([r.property for r in trajectory.records]) - target)
    best = trajectory.best
    assert distance[best] < distance[0] - 0.05
    assert distance[-1] < distance[0] - 0.05
    assert trajectory.total_loss[best] < trajectory.total_loss[0]
    assert trajectory.strain.max() < 10.0  # kcal/mol
    assert trajectory.strain.min() == 0.0


def test_heavier_strain_weight_allows_less_strain(structure) -> None:
    loose = run_inner_loop(structure, Objective("gap", -3.0, 0.01), steps=8)
    tight = run_inner_loop(structure, Objective("gap", -3.0, 1.0), steps=8)
    assert tight.strain[-1] < loose.strain[-1]
    assert abs(loose.records[-1].property - loose.records[0].property) > abs(
        tight.records[-1].property - tight.records[0].property
    )


def test_evaluation_reports_losses_curves_and_coordinates() -> None:
    settings = EvaluationSettings(epochs=4, learning_rate=0.02)
    evaluation = score(GapLowTask(), solution_for(SMILES), settings)
    assert evaluation.valid, evaluation.reason
    curves = evaluation.curves
    assert {"loss", "property", "strain"} <= set(curves)
    assert all(len(c) == 5 for c in curves.values())
    best = evaluation.extras["best_step"]
    assert evaluation.loss == pytest.approx(min(curves["loss"]))
    assert evaluation.loss == pytest.approx(curves["loss"][best])
    assert evaluation.parameters["property"] == pytest.approx(curves["property"][best])
    assert evaluation.parameters["gap"] == pytest.approx(evaluation.parameters["property"])
    expected = (curves["property"][best] + 2.0) ** 2 + 0.3 * curves["strain"][best]
    assert evaluation.loss == pytest.approx(expected)
    assert np.array(evaluation.extras["coordinates"]).shape == (9, 3)
    assert evaluation.extras["learning_rate"] == 0.02
    for phrase in ("Target", "before optimization", "Property loss", "Conformer loss", "Total"):
        assert phrase in evaluation.feedback
    assert "[" in evaluation.feedback.splitlines()[-2]
    assert evaluation.to_json()


def test_zero_epochs_scores_the_start(structure) -> None:
    evaluation = score(HomoTask(), solution_for(SMILES), EvaluationSettings(epochs=0))
    assert evaluation.valid
    assert len(evaluation.curves["loss"]) == 1
    assert evaluation.parameters["strain_kcal_mol"] == 0.0
