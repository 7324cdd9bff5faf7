"""MLS-MPM transfer kernels: particle-to-grid, grid update, grid-to-particle.

APIC transfer with quadratic B-splines (Hu et al. 2018). Arrays are time-indexed,
``x[slot, p]``, so no value is overwritten inside a recorded segment and Taichi's
autodiff needs no bookkeeping. The 27-node stencil is unrolled with ``ti.static``:
dynamic stencil loops gave wrong gradients in Taichi 1.7.
"""

import taichi as ti

from taichi_mpm.kernels.linalg import identity, matmul, matvec, outer, sum_terms

MASS_FLOOR = 1e-12  # grid velocity = momentum / max(mass, floor): no NaN gradients
SLIP, STICKY, SEPARATE = 0, 1, 2  # slip is SEPARATE with zero friction
TANGENT_TINY = 1e-20
STENCIL = [(i, j, k) for i in range(3) for j in range(3) for k in range(3)]  # 27 nodes


@ti.func
def stencil(xp, inv_dx, n):
    """Lower-corner node and quadratic B-spline weights of a particle."""
    Xp = xp * inv_dx
    base = ti.cast(ti.floor(Xp - 0.5), ti.i32)
    base = ti.max(ti.min(base, n - 3), 0)
    fx = Xp - ti.cast(base, float)
    w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1.0) ** 2, 0.5 * (fx - 0.5) ** 2]
    return base, fx, w


@ti.func
def apply_walls(v, node, n, kind, thickness, friction):
    """Box walls ``thickness`` cells deep on every face (slip is friction 0)."""
    for d in ti.static(range(3)):
        unit = ti.Vector([1.0 if e == d else 0.0 for e in ti.static(range(3))])
        low = node[d] < thickness
        high = node[d] >= n - thickness
        into_wall = ti.cast((low & (v[d] < 0)) | (high & (v[d] > 0)), float)
        near_wall = ti.cast(low | high, float)
        tangent = v - v[d] * unit
        speed = ti.sqrt(tangent.dot(tangent) + TANGENT_TINY)
        slid = tangent * ti.max(0.0, 1.0 - friction * ti.abs(v[d]) / speed)
        sticky = ti.cast(kind == STICKY, float)
        v = sticky * (1.0 - near_wall) * v + (1.0 - sticky) * (
            into_wall * slid + (1.0 - into_wall) * v
        )
    return v


@ti.func
def scatter(
    x: ti.template(),
    v: ti.template(),
    C: ti.template(),
    stress: ti.template(),
    slot,
    p,
    grid_mass: ti.template(),
    grid_momentum: ti.template(),
    dx,
    dt,
    particle_volume,
    particle_mass,
):
    """Particle p's mass, momentum and stress impulse onto its 27 grid nodes."""
    inv_dx = 1.0 / dx
    base, fx, w = stencil(x[slot, p], inv_dx, grid_mass.shape[1])
    impulse = (-dt * particle_volume * 4.0 * inv_dx * inv_dx) * stress[slot, p]
    affine = impulse + particle_mass * C[slot, p]
    momentum = particle_mass * v[slot, p]
    for i, j, k in ti.static(STENCIL):
        dpos = (ti.Vector([i, j, k], dt=float) - fx) * dx
        weight = w[i][0] * w[j][1] * w[k][2]
        node = base + ti.Vector([i, j, k])
        grid_momentum[slot, node[0], node[1], node[2]] += weight * (momentum + matvec(affine, dpos))
        grid_mass[slot, node[0], node[1], node[2]] += weight * particle_mass


@ti.func
def update_node(
    grid_mass: ti.template(),
    grid_momentum: ti.template(),
    slot,
    i,
    j,
    k,
    grid_velocity: ti.template(),
    dt,
    gravity,
    wall_kind,
    wall_thickness,
    wall_friction,
):
    """Velocity of node (i, j, k) from its momentum, plus gravity and the walls."""
    mass = grid_mass[slot, i, j, k]
    if mass > 0:  # most nodes are empty: skip them (G2P never reads them)
        v = grid_momentum[slot, i, j, k] / ti.max(mass, MASS_FLOOR) + dt * gravity
        grid_velocity[slot, i, j, k] = apply_walls(
            v, ti.Vector([i, j, k]), grid_mass.shape[1], wall_kind, wall_thickness, wall_friction
        )
    else:
        grid_velocity[slot, i, j, k] = ti.Vector.zero(float, 3)


@ti.func
def gather(
    x: ti.template(),
    v: ti.template(),
    C: ti.template(),
    F: ti.template(),
    F_corrected: ti.template(),
    grid_velocity: ti.template(),
    slot,
    p,
    dx,
    dt,
):
    """Particle p's velocity and affine velocity from the grid; its state at slot + 1."""
    inv_dx = 1.0 / dx
    base, fx, w = stencil(x[slot, p], inv_dx, grid_velocity.shape[1])
    momenta = [
        w[i][0] * w[j][1] * w[k][2] * grid_velocity[slot, base[0] + i, base[1] + j, base[2] + k]
        for i, j, k in ti.static(STENCIL)
    ]
    new_v = sum_terms(momenta, 0, 27)
    new_C = (4.0 * inv_dx) * sum_terms(
        [outer(momenta[n], ti.Vector(STENCIL[n], dt=float) - fx) for n in ti.static(range(27))],
        0,
        27,
    )
    v[slot + 1, p] = new_v
    C[slot + 1, p] = new_C
    x[slot + 1, p] = x[slot, p] + dt * new_v
    F[slot + 1, p] = matmul(identity() + dt * new_C, F_corrected[slot, p])


@ti.kernel
def p2g(
    x: ti.types.ndarray(),
    v: ti.types.ndarray(),
    C: ti.types.ndarray(),
    stress: ti.types.ndarray(),
    slot: ti.i32,
    grid_mass: ti.types.ndarray(),
    grid_momentum: ti.types.ndarray(),
    dx: float,
    dt: float,
    particle_volume: float,
    particle_mass: float,
    serial: ti.template(),
):
    """Scatter mass, momentum and the stress impulse of every particle to the grid."""
    ti.loop_config(serialize=serial)
    for p in range(x.shape[1]):
        scatter(
            x,
            v,
            C,
            stress,
            slot,
            p,
            grid_mass,
            grid_momentum,
            dx,
            dt,
            particle_volume,
            particle_mass,
        )


@ti.kernel
def grid_update(
    grid_mass: ti.types.ndarray(),
    grid_momentum: ti.types.ndarray(),
    slot: ti.i32,
    grid_velocity: ti.types.ndarray(),
    dt: float,
    gx: float,
    gy: float,
    gz: float,
    wall_kind: ti.i32,
    wall_thickness: ti.i32,
    wall_friction: float,
    serial: ti.template(),
):
    """Grid velocity from momentum, plus gravity and the box walls."""
    ti.loop_config(serialize=serial)
    for i, j, k in ti.ndrange(grid_mass.shape[1], grid_mass.shape[2], grid_mass.shape[3]):
        update_node(
            grid_mass,
            grid_momentum,
            slot,
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


@ti.kernel
def g2p(
    x: ti.types.ndarray(),
    v: ti.types.ndarray(),
    C: ti.types.ndarray(),
    F: ti.types.ndarray(),
    F_corrected: ti.types.ndarray(),
    grid_velocity: ti.types.ndarray(),
    slot: ti.i32,
    dx: float,
    dt: float,
    serial: ti.template(),
):
    """Gather velocity and affine velocity; advect; state of step slot + 1."""
    ti.loop_config(serialize=serial)
    for p in range(x.shape[1]):
        gather(x, v, C, F, F_corrected, grid_velocity, slot, p, dx, dt)
