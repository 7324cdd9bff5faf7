"""The kernels' argument packs (taichi_mpm.kernels.arguments)."""

import taichi as ti

from taichi_mpm.kernels.arguments import Grid, GridGrad, Records, State, model_types


def test_no_two_packs_share_a_member_name():
    """Taichi 1.7 keys a pack argument's arrays by member name alone: two packs of one kernel
    whose arrays share a name would get each other's arrays."""
    model = model_types(ti.f32)
    packs = (State, Grid, GridGrad, Records, model.material, model.constants)
    names = [name for pack in packs for name in pack.members]
    assert len(names) == len(set(names))


def test_model_types_hold_the_precision_they_are_made_for():
    for dtype in (ti.f32, ti.f64):
        model = model_types(dtype)
        assert model.constants.members["dt"] == dtype
        assert model.material.members["spectral_tol"] == dtype
        assert model_types(dtype) is model  # made once
