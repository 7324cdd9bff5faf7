"""How many teacher-forced segments the inner fit steps at once: as many as its graph budget
holds, and no more than ``batch_particles`` particles of scene copies."""

import pytest
import torch

from bridges.laws import from_material
from bridges.rollout import Rollout, State, segments_per_batch
from tasks.constitutive.ground_truth import Trajectory
from tasks.constitutive.inner import InnerSettings, segments_at_once
from tests.bridges.test_equivalence import MATERIALS
from tests.bridges.test_segment_batching import SEGMENT, _observation


@pytest.mark.parametrize(
    ("segments_in_budget", "copies_allowed", "expected"),
    [(3.5, 10, 3), (3.5, 2, 2), (3.5, 1, 1), (0, 10, 1)],
    ids=["budget-bound", "particle-bound", "one-copy", "tiny-budget"],
)
def test_the_batch_is_bounded_by_the_budget_and_the_particles(
    segments_in_budget, copies_allowed, expected
):
    material = MATERIALS["neo_hookean"]
    scene, observed, resets = _observation(material)
    plastic, elastic = from_material(material, dtype=torch.float64)
    rollout = Rollout(scene, plastic, elastic)
    start = State.from_arrays(resets, 0, torch.float64)
    segment_bytes = 2**40 // segments_per_batch(rollout, start, SEGMENT, 2**40)
    trajectory = Trajectory(observed, list(range(0, len(observed) - 1, SEGMENT)), resets)
    settings = InnerSettings(
        reset_every=SEGMENT,
        graph_memory_mb=max(segments_in_budget * segment_bytes / 2**20, 1e-9),
        batch_particles=copies_allowed * scene.num_particles + scene.num_particles // 2,
    )
    assert segments_at_once(rollout, trajectory, settings) == expected


def test_a_batch_of_no_particles_is_refused():
    from tasks.constitutive.options import ConstitutiveOptions

    with pytest.raises(ValueError, match="batch_particles"):
        ConstitutiveOptions(batch_particles=0)
