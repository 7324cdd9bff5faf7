"""Small bookkeeping kernels that move per-particle values between time slots."""

import taichi as ti


@ti.kernel
def copy_slot(
    source: ti.types.ndarray(), source_slot: ti.i32, target: ti.types.ndarray(), target_slot: ti.i32
):
    """target[target_slot, :] = source[source_slot, :]."""
    for p in range(source.shape[1]):
        target[target_slot, p] = source[source_slot, p]


@ti.kernel
def add_to_slot(target: ti.types.ndarray(), slot: ti.i32, values: ti.types.ndarray()):
    """target[slot, :] += values[:] (seeds a loss gradient into a recorded frame)."""
    for p in range(values.shape[0]):
        target[slot, p] += values[p]


@ti.kernel
def clear(values: ti.types.ndarray()):
    """Zero every element."""
    for index in ti.grouped(values):
        values[index] = ti.zero(values[index])
