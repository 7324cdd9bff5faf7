"""The bridge's hand-written reverse of a step equals Taichi's autodiff of the same step.

taichi_mpm differentiates its per-phase kernels (P2G, grid update, G2P) with Taichi's
autodiff; the bridge runs the hand-written adjoints of
:mod:`taichi_mpm.kernels.transfer_adjoint` instead. On one step of random states, particles
against every kind of wall included, the two give the same next state and the same input
gradients to round-off (float64).
"""

import numpy as np
import pytest
import taichi as ti
import torch

import taichi_mpm as tm
from bridges import kernels
from bridges.step import Transfer, mpm_step
from taichi_mpm.kernels.arguments import CARRIED, step_constants
from taichi_mpm.kernels.transfer import phase_kernels
from tests.taichi_mpm.helpers import impact_scene

WALLS = {
    "slip": tm.Walls("slip", thickness=3),
    "sticky": tm.Walls("sticky", thickness=3),
    "separate": tm.Walls("separate", thickness=3, friction=0.4),
}


def _random_step(scene: tm.Scene, seed: int):
    """Inputs (x, v, C, F, stress) and output weights of one step, float64 tensors."""
    rng = np.random.default_rng(seed)
    N = scene.num_particles
    x = scene.positions + 0.01 * rng.standard_normal((N, 3))
    x[: N // 4, 1] = 0.16 + 0.02 * rng.random(N // 4)  # inside the floor's wall cells
    inputs = [
        x,
        scene.velocities + rng.standard_normal((N, 3)),
        3.0 * rng.standard_normal((N, 3, 3)),
        np.eye(3) + 0.05 * rng.standard_normal((N, 3, 3)),
        2e3 * rng.standard_normal((N, 3, 3)),
    ]
    weights = [rng.standard_normal(shape) for shape in ((N, 3), (N, 3), (N, 3, 3), (N, 3, 3))]
    return [torch.tensor(a) for a in inputs], [torch.tensor(w) for w in weights]


def _bridge_gradients(scene, inputs, weights):
    leaves = [t.clone().requires_grad_(True) for t in inputs]
    outputs = mpm_step(*leaves, Transfer(scene))
    sum((w * o).sum() for w, o in zip(weights, outputs, strict=True)).backward()
    return [leaf.grad.numpy() for leaf in leaves], [o.detach().numpy() for o in outputs]


def _autodiff_gradients(scene, inputs, weights):
    """The same step through taichi_mpm's kernels and Taichi's autodiff of them."""
    n, N = scene.grid_resolution, scene.num_particles
    vec, mat = ti.types.vector(3, ti.f64), ti.types.matrix(3, 3, ti.f64)

    def array(element, shape):
        return ti.ndarray(element, shape=shape, needs_grad=True)

    x, v = array(vec, (2, N)), array(vec, (2, N))
    C, F = array(mat, (2, N)), array(mat, (2, N))
    F_corrected, stress = array(mat, (1, N)), array(mat, (1, N))
    grid_mass = array(ti.f64, (1, n**3))
    grid_momentum, grid_velocity = array(vec, (1, n**3)), array(vec, (1, n**3))
    values = np.zeros((2, N, 3)), np.zeros((2, N, 3)), np.zeros((2, N, 3, 3))
    for target, value in zip(values, inputs[:3], strict=True):
        target[0] = value.numpy()
    x.from_numpy(values[0])
    v.from_numpy(values[1])
    C.from_numpy(values[2])
    F_corrected.from_numpy(inputs[3].numpy()[None])
    stress.from_numpy(inputs[4].numpy()[None])
    constants = step_constants(scene)
    tk = phase_kernels(ti.f64)
    p2g_args = (x, v, C, stress, grid_mass, grid_momentum, 0, constants, True)
    grid_args = (grid_mass, grid_momentum, grid_velocity, 0, constants, True)
    g2p_args = (x, v, C, F, F_corrected, grid_velocity, 0, constants, True)
    tk.p2g(*p2g_args)
    tk.grid_update(*grid_args)
    tk.g2p(*g2p_args)
    for array_, weight in zip((x, v, C, F), weights, strict=True):
        seed = np.zeros((2, *weight.shape))
        seed[1] = weight.numpy()
        array_.grad.from_numpy(seed)
    tk.g2p.grad(*g2p_args)
    tk.grid_update.grad(*grid_args)
    tk.p2g.grad(*p2g_args)
    grads = [x.grad.to_numpy()[0], v.grad.to_numpy()[0], C.grad.to_numpy()[0],
             F_corrected.grad.to_numpy()[0], stress.grad.to_numpy()[0]]  # fmt: skip
    outputs = [a.to_numpy()[1] for a in (x, v, C, F)]
    return grads, outputs


@pytest.mark.parametrize("wall", list(WALLS))
def test_hand_written_reverse_equals_taichi_autodiff(wall):
    scene = impact_scene(steps=1, walls=WALLS[wall])
    inputs, weights = _random_step(scene, seed=len(wall))
    bridge, bridge_outputs = _bridge_gradients(scene, inputs, weights)
    autodiff, outputs = _autodiff_gradients(scene, inputs, weights)
    for got, expected in zip(bridge_outputs, outputs, strict=True):
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())
    for name, got, expected in zip(["x", "v", "C", "F", "stress"], bridge, autodiff, strict=True):
        scale = np.abs(expected).max()
        assert scale > 0, name
        np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-10 * scale, err_msg=name)


def _step_and_gradients(transfer, inputs, weights):
    leaves = [t.clone().requires_grad_(True) for t in inputs]
    outputs = mpm_step(*leaves, transfer)
    sum((w * o).sum() for w, o in zip(weights, outputs, strict=True)).backward()
    return [o.detach().numpy() for o in outputs] + [leaf.grad.numpy() for leaf in leaves]


def test_serial_loops_over_occupied_boxes_equal_parallel_loops_over_the_grid():
    """Serial launches visit only each copy's occupied box and leave stale nodes outside it;
    a Transfer that stepped a body elsewhere first must still give what full-grid loops give."""
    scene = impact_scene(steps=1, walls=WALLS["separate"])
    inputs, weights = _random_step(scene, seed=7)
    elsewhere = [t.clone() for t in inputs]
    elsewhere[0] = elsewhere[0] + torch.tensor([0.2, 0.3, -0.1], dtype=torch.float64)
    full_grid = _step_and_gradients(Transfer(scene, parallel=True), inputs, weights)
    boxed = Transfer(scene, parallel=False)
    _step_and_gradients(boxed, elsewhere, weights)  # fills other nodes of the grid first
    for got, expected in zip(_step_and_gradients(boxed, inputs, weights), full_grid, strict=True):
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())


def test_packed_rows_follow_the_carried_state():
    """The kernels' column offsets are those of the fields the step packs, in their order."""
    starts = np.cumsum([0] + [np.prod(shape) for shape in kernels.INPUT_FIELDS.values()])
    assert list(kernels.INPUT_FIELDS)[: len(CARRIED)] == list(CARRIED)
    columns = [kernels.COL_X, kernels.COL_V, kernels.COL_C, kernels.COL_F, kernels.COL_STRESS]
    widths = (kernels.STATE_WIDTH, kernels.PACKED_WIDTH)
    assert columns == list(starts[:-1])
    assert widths == (starts[len(CARRIED)], starts[-1])


def test_a_step_computes_a_hencky_stress_again_instead_of_keeping_it():
    """A stress that carries a recipe (the Taichi Hencky stress) is not kept by the step: its
    reverse computes it again from F and the compact SVD, which the stress's own node keeps.
    Outputs and gradients (of x, v, C, the trial F and the Lame parameters) equal those of the
    same step given the stress without its recipe."""
    from bridges.hencky import hencky_stress
    from bridges.step import recipe_of

    scene = impact_scene(steps=1, walls=WALLS["slip"])
    inputs, weights = _random_step(scene, seed=11)
    results = []
    for keep_stress in (False, True):
        x, v, C, F = (t.clone().requires_grad_(True) for t in inputs[:4])
        mu, lam = (torch.tensor(value, dtype=torch.float64, requires_grad=True)
                   for value in (3e4, 2e4))  # fmt: skip
        stress = hencky_stress(F, mu, lam)
        assert recipe_of(stress) is not None
        if keep_stress:
            stress = stress.clone()  # no recipe: the step keeps it
        outputs = mpm_step(x, v, C, F, stress, Transfer(scene))
        kept = {t.untyped_storage().data_ptr() for t in outputs[0].grad_fn.saved_tensors}
        assert (stress.untyped_storage().data_ptr() in kept) == keep_stress
        sum((w * o).sum() for w, o in zip(weights, outputs, strict=True)).backward()
        results.append([*(o.detach() for o in outputs), *(t.grad for t in (x, v, C, F, mu, lam))])
    for got, expected in zip(*results, strict=True):
        torch.testing.assert_close(got, expected, rtol=1e-12, atol=1e-12 * expected.abs().max())
