"""Whole MPM steps in one launch, for the forward pass.

The forward pass records everything the reverse pass reads, so it need not run phase by
phase: :func:`advance` runs many steps of a small scene in one serial kernel (a Taichi
launch with ndarray arguments costs 15-50 us, more than a 1000-particle phase), and
:func:`step_parallel` runs one step of a large scene with parallel loops. Both run
:func:`mpm_step`, which calls the same Taichi functions as the per-phase kernels that
the reverse pass differentiates.
"""

import taichi as ti

from taichi_mpm.kernels.constitutive import constitutive_update
from taichi_mpm.kernels.transfer import gather, scatter, update_node


@ti.func
def mpm_step(
    s,
    a: ti.template(),
    n,
    elastic_kind,
    share,
    tol,
    dx,
    dt,
    volume,
    mass,
    gx,
    gy,
    gz,
    kind,
    thickness,
    friction,
):
    """Slot s to s + 1: laws, clear grid slot s, P2G, grid update, G2P.

    ``a`` is the compile-time tuple of the arrays :func:`advance` takes, n the grid
    resolution (a grid slot is a flat row of n^3 nodes), the rest its scalars. Called at a
    kernel's top level its loops run in parallel; called inside a serial loop they run
    serially.
    """
    x, v, C, F, Fc, stress, grid_mass, grid_momentum, grid_velocity = ti.static(a[:9])
    for p in range(x.shape[1]):
        constitutive_update(
            F,
            Fc,
            stress,
            s,
            p,
            a[9],
            a[10],
            a[11],
            a[12],
            a[13],
            a[14],
            a[15],
            a[16],
            elastic_kind,
            share,
            tol,
        )
    for q in range(grid_mass.shape[1]):
        grid_mass[s, q] = 0.0
        grid_momentum[s, q] = ti.Vector.zero(float, 3)
    for p in range(x.shape[1]):
        scatter(x, v, C, stress, s, p, grid_mass, grid_momentum, n, dx, dt, volume, mass)
    for q in range(grid_mass.shape[1]):
        update_node(grid_mass, grid_momentum, s, q, n, grid_velocity, dt,
                    ti.Vector([gx, gy, gz]), kind, thickness, friction)  # fmt: skip
    for p in range(x.shape[1]):
        gather(x, v, C, F, Fc, grid_velocity, s, p, n, dx, dt)


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
    grid_resolution: ti.i32,
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
    """Slots first .. last - 1 advanced to first + 1 .. last, serially, in one launch."""
    arrays = ti.static(
        (
            x,
            v,
            C,
            F,
            F_corrected,
            stress,
            grid_mass,
            grid_momentum,
            grid_velocity,
            params,
            trial_U,
            trial_V,
            coeff_von_mises,
            coeff_sand,
            elastic_U,
            elastic_V,
            coeff_elastic,
        )
    )
    ti.loop_config(serialize=True)
    for s in range(first, last):
        mpm_step(
            s,
            arrays,
            grid_resolution,
            elastic_kind,
            share_basis,
            tol,
            dx,
            dt,
            particle_volume,
            particle_mass,
            gx,
            gy,
            gz,
            wall_kind,
            wall_thickness,
            wall_friction,
        )


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
    grid_resolution: ti.i32,
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
    arrays = ti.static(
        (
            x,
            v,
            C,
            F,
            F_corrected,
            stress,
            grid_mass,
            grid_momentum,
            grid_velocity,
            params,
            trial_U,
            trial_V,
            coeff_von_mises,
            coeff_sand,
            elastic_U,
            elastic_V,
            coeff_elastic,
        )
    )
    mpm_step(
        s,
        arrays,
        grid_resolution,
        elastic_kind,
        share_basis,
        tol,
        dx,
        dt,
        particle_volume,
        particle_mass,
        gx,
        gy,
        gz,
        wall_kind,
        wall_thickness,
        wall_friction,
    )
