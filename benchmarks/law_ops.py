"""Microseconds of a law's 3x3 determinant, inverse and product: torch against ours.

Determinant and inverse: torch's LU against the closed forms (``bridges.closed_form``); the
batched product ``F @ F.mT``: ``torch.bmm`` against the Taichi kernel (``bridges.products``).

A teacher-forced epoch evaluates the law on one batch of 10 scene copies (10,000 particles)
100 times, forward and backward, so these are per-step costs. Each operation runs on a
(B, 3, 3) batch of deformation gradients near the identity; the table gives the median over
``--repeats`` timed calls of the forward alone and of forward + backward, interleaving the
torch and closed-form variants. Usage::

    python benchmarks/law_ops.py [--batch 10000] [--threads 1] [--dtype float32]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable

import torch

import taichi_mpm as tm
from bridges.closed_form import det3, inv3
from bridges.products import bmm3

OPERATIONS: dict[str, dict[str, Callable[[torch.Tensor], torch.Tensor]]] = {
    "determinant": {"torch (LU)": torch.linalg.det, "closed form": det3},
    "inverse": {"torch (LU)": torch.linalg.inv, "closed form": inv3},
    "product": {"torch (bmm)": lambda F: F @ F.mT, "Taichi": lambda F: bmm3(F, F.mT)},
}


def one_call(operation: Callable, F: torch.Tensor, backward: bool) -> float:
    started = time.perf_counter()
    out = operation(F)
    if backward:
        out.backward(torch.ones_like(out))
    return time.perf_counter() - started


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=10_000)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--dtype", choices=["float32", "float64"], default="float32")
    parser.add_argument("--repeats", type=int, default=200)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    tm.init(arch="cpu", precision=args.dtype, cpu_max_num_threads=args.threads)
    generator = torch.Generator().manual_seed(0)
    dtype = getattr(torch, args.dtype)
    noise = torch.randn(args.batch, 3, 3, generator=generator, dtype=dtype)
    F = (torch.eye(3, dtype=dtype) + 0.05 * noise).requires_grad_(True)
    print(f"{os.cpu_count()} cores; load average before {os.getloadavg()}; batch {args.batch}, "
          f"{args.dtype}, {args.threads} torch thread(s), median of {args.repeats}")  # fmt: skip
    print(f"{'operation':<12} {'variant':<12} {'forward us':>11} {'fwd+bwd us':>11}")
    for name, variants in OPERATIONS.items():
        times: dict[tuple[str, bool], list[float]] = {}
        for _ in range(args.repeats):
            for variant, operation in variants.items():
                for backward in (False, True):
                    times.setdefault((variant, backward), []).append(
                        one_call(operation, F, backward)
                    )
        for variant in variants:
            forward = statistics.median(times[variant, False]) * 1e6
            both = statistics.median(times[variant, True]) * 1e6
            print(f"{name:<12} {variant:<12} {forward:>11.0f} {both:>11.0f}")
    print(f"load average after {os.getloadavg()}")


if __name__ == "__main__":
    main()
