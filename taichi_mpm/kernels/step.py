"""Whole MPM steps in one launch, for the forward pass.

The forward pass records everything the reverse pass reads, so it need not run phase by
phase: :func:`advance` runs many steps of a small scene in one serial kernel (a Taichi
launch with ndarray arguments costs 15-50 us, more than a 1000-particle phase), and
:func:`step_parallel` runs one step of a large scene with parallel loops. Both call the
same Taichi functions as the per-phase kernels that the reverse pass differentiates.
"""

import taichi as ti

from taichi_mpm.kernels.constitutive import constitutive_update
from taichi_mpm.kernels.transfer import gather, scatter, update_node


@ti.kernel
def advance(
    x: ti.types.ndarray(),
    v: ti.types.ndarray(),
    C: ti.types.ndarray(),
    F: ti.types.ndarray(),
    F_corrected: ti.types.ndarray(),
    stress: ti.types.ndarray(),
    grid_mass: ti.types.ndarray(),
    grid_momentum: ti.types.ndarray(),
    grid_velocity: ti.types.ndarray(),
    params: ti.types.ndarray(),
    trial_U: ti.types.ndarray(),
    trial_V: ti.types.ndarray(),
    coeff_von_mises: ti.types.ndarray(),
    coeff_sand: ti.types.ndarray(),
    elastic_U: ti.types.ndarray(),
    elastic_V: ti.types.ndarray(),
    coeff_elastic: ti.types.ndarray(),
    first: ti.i32,
    last: ti.i32,
    elastic_kind: ti.i32,
    share_basis: ti.i32,
    tol: float,
    dx: float,
    dt: float,
    particle_volume: float,
    particle_mass: float,
    gx: float,
    gy: float,
    gz: float,
    wall_kind: ti.i32,
    wall_thickness: ti.i32,
    wall_friction: float,
):
    """Slots first .. last - 1 advanced to first + 1 .. last, serially, in one launch.

    Each step clears its own grid slot first, so no array needs clearing beforehand.
    """
    ti.loop_config(serialize=True)
    for s in range(first, last):
        for p in range(x.shape[1]):
            constitutive_update(
                F,
                F_corrected,
                stress,
                s,
                p,
                params,
                trial_U,
                trial_V,
                coeff_von_mises,
                coeff_sand,
                elastic_U,
                elastic_V,
                coeff_elastic,
                elastic_kind,
                share_basis,
                tol,
            )
        n = grid_mass.shape[1]
        for i, j, k in ti.ndrange(n, n, n):
            grid_mass[s, i, j, k] = 0.0
            grid_momentum[s, i, j, k] = ti.Vector.zero(float, 3)
        for p in range(x.shape[1]):
            scatter(
                x,
                v,
                C,
                stress,
                s,
                p,
                grid_mass,
                grid_momentum,
                dx,
                dt,
                particle_volume,
                particle_mass,
            )
        for i, j, k in ti.ndrange(n, n, n):
            update_node(
                grid_mass,
                grid_momentum,
                s,
                i,
                j,
                k,
                grid_velocity,
                dt,
                ti.Vector([gx, gy, gz]),
                wall_kind,
                wall_thickness,
                wall_friction,
            )
        for p in range(x.shape[1]):
            gather(x, v, C, F, F_corrected, grid_velocity, s, p, dx, dt)


@ti.kernel
def step_parallel(
    x: ti.types.ndarray(),
    v: ti.types.ndarray(),
    C: ti.types.ndarray(),
    F: ti.types.ndarray(),
    F_corrected: ti.types.ndarray(),
    stress: ti.types.ndarray(),
    grid_mass: ti.types.ndarray(),
    grid_momentum: ti.types.ndarray(),
    grid_velocity: ti.types.ndarray(),
    params: ti.types.ndarray(),
    trial_U: ti.types.ndarray(),
    trial_V: ti.types.ndarray(),
    coeff_von_mises: ti.types.ndarray(),
    coeff_sand: ti.types.ndarray(),
    elastic_U: ti.types.ndarray(),
    elastic_V: ti.types.ndarray(),
    coeff_elastic: ti.types.ndarray(),
    s: ti.i32,
    elastic_kind: ti.i32,
    share_basis: ti.i32,
    tol: float,
    dx: float,
    dt: float,
    particle_volume: float,
    particle_mass: float,
    gx: float,
    gy: float,
    gz: float,
    wall_kind: ti.i32,
    wall_thickness: ti.i32,
    wall_friction: float,
):
    """Slot s advanced to s + 1 with parallel loops (arguments as :func:`advance`, one slot)."""
    for p in range(x.shape[1]):
        constitutive_update(
            F,
            F_corrected,
            stress,
            s,
            p,
            params,
            trial_U,
            trial_V,
            coeff_von_mises,
            coeff_sand,
            elastic_U,
            elastic_V,
            coeff_elastic,
            elastic_kind,
            share_basis,
            tol,
        )
    for i, j, k in ti.ndrange(grid_mass.shape[1], grid_mass.shape[2], grid_mass.shape[3]):
        grid_mass[s, i, j, k] = 0.0
        grid_momentum[s, i, j, k] = ti.Vector.zero(float, 3)
    for p in range(x.shape[1]):
        scatter(
            x, v, C, stress, s, p, grid_mass, grid_momentum, dx, dt, particle_volume, particle_mass
        )
    for i, j, k in ti.ndrange(grid_mass.shape[1], grid_mass.shape[2], grid_mass.shape[3]):
        update_node(
            grid_mass,
            grid_momentum,
            s,
            i,
            j,
            k,
            grid_velocity,
            dt,
            ti.Vector([gx, gy, gz]),
            wall_kind,
            wall_thickness,
            wall_friction,
        )
    for p in range(x.shape[1]):
        gather(x, v, C, F, F_corrected, grid_velocity, s, p, dx, dt)
