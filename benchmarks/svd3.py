"""Milliseconds of a batched 3x3 SVD: the bridge's Jacobi kernel against Taichi's ``ti.svd``.

Both run over the same (B, 9) float32 batch of deformation gradients near the identity in one
serial Taichi kernel (the bridge's loops are serial below ``PARALLEL_MIN_PARTICLES``): the
bridge's own ``svd3``, and the same kernel with ``ti.svd`` in place of the Jacobi SVD; the
table gives the median over ``--repeats`` launches of each, interleaved, and the accuracy of
each against LAPACK in float64. Usage::

    python benchmarks/svd3.py [--batch 5000] [--repeats 50]
"""

import argparse
import os
import statistics
import time

import taichi as ti
import torch

import taichi_mpm as tm
from bridges.kernels import _mat, _put_mat, svd3


@ti.kernel
def taichi_own(F: ti.types.ndarray(), out: ti.types.ndarray()):
    """``bridges.kernels.svd3`` (serial) with ``ti.svd``."""
    ti.loop_config(serialize=True)
    for p in range(F.shape[0]):
        u, s, v = ti.svd(_mat(F, p, 0))
        _put_mat(out, p, 0, u)
        for i in ti.static(range(3)):
            out[p, 9 + i] = s[i, i]
        _put_mat(out, p, 12, v)


def accuracy(out: torch.Tensor, F: torch.Tensor) -> tuple[float, float]:
    """Largest reconstruction error and singular-value error (against LAPACK, float64)."""
    U, S, V = out[:, :9].reshape(-1, 3, 3), out[:, 9:12], out[:, 12:].reshape(-1, 3, 3)
    matrices = F.reshape(-1, 3, 3)
    reconstruction = (U @ torch.diag_embed(S) @ V.mT - matrices).abs().max().item()
    values = (S.abs().double() - torch.linalg.svdvals(matrices.double())).abs().max().item()
    return reconstruction, values


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=5000)
    parser.add_argument("--repeats", type=int, default=50)
    args = parser.parse_args()
    tm.init(arch="cpu", precision="float32")
    generator = torch.Generator().manual_seed(0)
    F = torch.eye(3) + 0.1 * torch.randn(args.batch, 3, 3, generator=generator)
    F = F.reshape(-1, 9).contiguous()
    kernels = {
        "Jacobi (bridge)": lambda matrices, out: svd3(matrices, out, True),
        "ti.svd": taichi_own,
    }
    outputs = {name: torch.empty(args.batch, 21) for name in kernels}
    for name, kernel in kernels.items():
        kernel(F, outputs[name])  # compile
    times: dict[str, list[float]] = {name: [] for name in kernels}
    for _ in range(args.repeats):
        for name, kernel in kernels.items():
            started = time.perf_counter()
            kernel(F, outputs[name])
            times[name].append(time.perf_counter() - started)
    print(f"{os.cpu_count()} cores; load average {os.getloadavg()}; {args.batch} matrices, "
          f"float32, serial loop, median of {args.repeats}")  # fmt: skip
    print(f"{'kernel':<16} {'ms':>7} {'reconstruction':>15} {'values':>9}")
    for name in kernels:
        reconstruction, values = accuracy(outputs[name], F)
        milliseconds = statistics.median(times[name]) * 1e3
        print(f"{name:<16} {milliseconds:>7.2f} {reconstruction:>15.1e} {values:>9.1e}")


if __name__ == "__main__":
    main()
