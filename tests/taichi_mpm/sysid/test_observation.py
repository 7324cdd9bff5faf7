"""The observation file format: round trip, and clear errors for malformed observations."""

import numpy as np
import pytest

import taichi_mpm as tm
from taichi_mpm.sysid import (
    Observation,
    ObservationError,
    load_observation,
    observation_from_times,
    save_observation,
)

DT = 1e-3


def small_scene() -> tm.Scene:
    positions, volume = tm.cube((0.5, 0.4, 0.5), 0.2, 3)
    velocities = tm.rigid_velocity(positions, (0.5, -1.0, 0.0), (0.0, 2.0, 0.0))
    return tm.Scene(
        positions,
        velocities,
        volume,
        density=800.0,
        grid_resolution=16,
        dt=DT,
        steps=30,
        gravity=(0.0, -9.8, 0.5),
        walls=tm.Walls("separate", thickness=2, friction=0.3),
    )


def fake_positions(scene: tm.Scene, frames: int = 4) -> np.ndarray:
    """(frames, N, 3) positions drifting with the initial velocity (no simulation needed)."""
    t = np.arange(1, frames + 1)[:, None, None] * 5 * DT
    return scene.positions[None] + t * scene.velocities[None]


def observation(frames: int = 4, indices=None) -> Observation:
    scene = small_scene()
    positions = fake_positions(scene, frames)
    if indices is not None:
        positions = positions[:, indices]
    return observation_from_times(scene, positions, np.arange(1, frames + 1) * 5 * DT, indices)


def test_round_trip_keeps_every_field(tmp_path):
    indices = np.array([0, 3, 7, 20, 26])
    original = observation(indices=indices)
    path = save_observation(tmp_path / "obs.npz", original)
    assert path.is_file()
    loaded = load_observation(path)

    np.testing.assert_array_equal(loaded.positions, original.positions)
    np.testing.assert_array_equal(loaded.frame_steps, [5, 10, 15, 20])
    np.testing.assert_allclose(loaded.times, original.times)
    np.testing.assert_array_equal(loaded.particle_indices, indices)
    a, b = loaded.scene, original.scene
    np.testing.assert_array_equal(a.positions, b.positions)
    np.testing.assert_array_equal(a.velocities, b.velocities)
    for name in ("particle_volume", "density", "grid_resolution", "domain_size", "dt", "steps"):
        assert getattr(a, name) == getattr(b, name), name
    assert a.steps == 20  # the scene runs up to the last observed frame
    assert a.gravity == (0.0, -9.8, 0.5)
    assert a.walls == tm.Walls("separate", thickness=2, friction=0.3)
    assert loaded.body_size == pytest.approx(original.body_size)


def test_particle_indices_default_to_all_particles(tmp_path):
    path = save_observation(tmp_path / "all.npz", observation())
    data = dict(np.load(path))
    del data["particle_indices"]  # optional in the format
    np.savez(tmp_path / "no_indices.npz", **data)
    loaded = load_observation(tmp_path / "no_indices.npz")
    np.testing.assert_array_equal(loaded.particle_indices, np.arange(27))


def test_wrong_positions_shape():
    scene = small_scene()
    positions = fake_positions(scene)
    with pytest.raises(
        ObservationError,
        match=r"shape \(frames, particles, 3\) with at least one particle, got \(4, 27, 2\)",
    ):
        Observation(scene, positions[..., :2], [5, 10, 15, 20], np.arange(27))
    with pytest.raises(
        ObservationError,
        match=r"shape \(frames, particles, 3\) with at least one particle, got \(4, 81\)",
    ):
        Observation(scene, positions.reshape(4, -1), [5, 10, 15, 20], np.arange(27))


def test_nan_in_positions():
    scene = small_scene()
    positions = fake_positions(scene)
    positions[2, 5, 1] = np.nan
    with pytest.raises(ObservationError, match="NaN or inf"):
        observation_from_times(scene, positions, np.arange(1, 5) * 5 * DT)


def test_too_few_frames():
    scene = small_scene()
    positions = fake_positions(scene, frames=2)
    positions[0] = scene.positions  # the frame at t = 0 does not count
    with pytest.raises(ObservationError, match="at least 2 frames after t = 0.*got 1"):
        observation_from_times(scene, positions, [0.0, 5 * DT])


def test_frame_and_time_counts_must_agree():
    scene = small_scene()
    with pytest.raises(ObservationError, match="4 frames of positions but"):
        observation_from_times(scene, fake_positions(scene), [5 * DT, 10 * DT, 15 * DT])


def test_times_must_be_increasing():
    scene = small_scene()
    with pytest.raises(ObservationError, match="strictly increasing"):
        observation_from_times(scene, fake_positions(scene), [5 * DT, 15 * DT, 10 * DT, 20 * DT])


def test_times_not_multiples_of_dt():
    scene = small_scene()
    times = np.array([5, 10, 15.5, 20]) * DT
    with pytest.raises(ObservationError, match=r"multiples of dt=0\.001.*resample"):
        observation_from_times(scene, fake_positions(scene), times)


def test_missing_keys(tmp_path):
    path = save_observation(tmp_path / "obs.npz", observation())
    data = dict(np.load(path))
    del data["dt"], data["walls"]
    np.savez(tmp_path / "partial.npz", **data)
    with pytest.raises(ObservationError) as error:
        load_observation(tmp_path / "partial.npz")
    message = str(error.value)
    assert "partial.npz" in message and "lacks" in message
    assert "'dt'" in message and "'walls'" in message
    assert "'positions'" not in message  # only the missing keys are named
    assert "save_observation" in message  # and how to write a complete file


def test_file_that_is_not_npz(tmp_path):
    text = tmp_path / "notes.npz"
    text.write_text("frame,x,y,z\n0,0.1,0.2,0.3\n")
    with pytest.raises(ObservationError, match=r"notes\.npz' is not a NumPy \.npz archive"):
        load_observation(text)


def test_missing_file(tmp_path):
    with pytest.raises(ObservationError, match="no observation file at"):
        load_observation(tmp_path / "absent.npz")
    with pytest.raises(ObservationError, match="no observation file at"):
        load_observation(tmp_path)  # a folder


def test_particle_indices_out_of_range(tmp_path):
    scene = small_scene()
    positions = fake_positions(scene)[:, :3]
    times = np.arange(1, 5) * 5 * DT
    for indices in ([0, 1, 27], [-1, 0, 1]):
        with pytest.raises(ObservationError, match=r"particle_indices must lie in \[0, 27\)"):
            observation_from_times(scene, positions, times, np.array(indices))
    with pytest.raises(ObservationError, match=r"particle_indices has shape \(2,\), expected \(3,"):
        observation_from_times(scene, positions, times, np.array([0, 1]))

    # the same check when reading a file
    path = save_observation(tmp_path / "obs.npz", observation(indices=np.array([0, 1, 2])))
    data = dict(np.load(path))
    data["particle_indices"] = np.array([0, 1, 99])
    np.savez(tmp_path / "bad_indices.npz", **data)
    with pytest.raises(ObservationError, match=r"particle_indices must lie in \[0, 27\)"):
        load_observation(tmp_path / "bad_indices.npz")


def test_negative_times_fractional_indices_and_empty_subsets_are_refused():
    scene = small_scene()
    positions = fake_positions(scene)
    with pytest.raises(ObservationError, match=">= 0 and strictly increasing"):
        Observation(scene, positions, [-5, 10, 15, 20], np.arange(27))
    with pytest.raises(ObservationError, match="whole numbers"):
        Observation(scene, positions, [5, 10, 15, 20], np.arange(27) + 0.5)
    with pytest.raises(ObservationError, match="at least one particle"):
        Observation(scene, positions[:, :0], [5, 10, 15, 20], np.arange(0))


def test_a_single_array_file_is_not_an_observation(tmp_path):
    path = tmp_path / "positions.npy"
    np.save(path, np.zeros((3, 4, 3)))
    with pytest.raises(ObservationError, match="single array"):
        load_observation(path)


def test_save_observation_returns_the_path_it_wrote(tmp_path):
    scene = small_scene()
    observation = Observation(scene, fake_positions(scene), [5, 10, 15, 20], np.arange(27))
    written = save_observation(tmp_path / "observed", observation)
    assert written == tmp_path / "observed.npz" and written.is_file()
