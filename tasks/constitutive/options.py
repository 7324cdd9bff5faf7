"""The options of the constitutive-law tasks (``--option KEY=VALUE``); plain data."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal


@dataclass(frozen=True)
class ConstitutiveOptions:
    """``steps``: steps of the scene (a shorter one for quick checks; default the task's 1000).
    ``optimizer``: the inner optimizer (default the task's: Adam, L-BFGS for ``imaginary``).
    ``precision``: Taichi's floating-point type (default: the running Taichi's, else float32);
    it must match a Taichi already running in the process.
    ``graph_memory_mb``: autograd graph the inner fit may hold at once (default 120 MB): the
    teacher-forced segments of an epoch run in batches of scene copies as large as fit in it
    (faster, more memory; ``bridges.rollout.segments_per_batch`` measures it on the law at
    hand), in as few batches as fit and as even as they can be. The default holds four of the
    paper scene's segments with a compiled plastic law (about 26 MB each) and five elastic ones
    (13 MB each), an evaluation's peak under 550 MB (``benchmarks/evaluate_speed.py``,
    docs/benchmarks.md).
    ``batch_particles``: particles of the copies in one batch at most (default 5,000: five
    copies of the paper's 1000-particle scene). Larger batches hold more graph for little or
    no speed: on the elastic task two batches of five copies were as fast as one of ten, at a
    peak 139 MB lower (``benchmarks/evaluate_speed.py``, docs/benchmarks.md).
    ``law_kernels``: which captured laws run compiled into Taichi kernels, one launch forward
    and one in reverse a step, where the translation covers their operations and agrees with
    torch (:mod:`tasks.constitutive.law_kernel`): ``auto`` (default) is ``all`` for a full fit
    and ``no-svd`` for a screen (a fit too short to repay compiling the sweeps); ``all`` every
    law the translation covers, its SVDs written out in the kernels as Jacobi sweeps (a von
    Mises law's step took 4.6 ms against torch's 6.4 ms, and its graph keeps less, for 0.75 s
    of compiling on a quiet machine: ``benchmarks/svd_law_kernels.py``); ``no-svd`` those
    without an SVD;
    ``svd-inputs`` also those whose SVDs are of F itself (the genetic-programming laws, the
    example plastic laws), computed once a step by the batched svd3 kernel and read by the
    law's kernels as inputs (compiled in about 0.15 s, a step about as fast as torch's);
    ``none`` keeps every law in torch."""

    steps: int | None = None
    optimizer: Literal["adam", "lbfgs"] | None = None
    precision: Literal["float32", "float64"] | None = None
    graph_memory_mb: float = 120.0
    batch_particles: int = 5_000
    law_kernels: Literal["auto", "all", "no-svd", "svd-inputs", "none"] = "auto"

    def __post_init__(self) -> None:
        if self.steps is not None and self.steps < 1:
            raise ValueError(f"option 'steps' must be at least 1, got {self.steps}")
        if not self.graph_memory_mb > 0:
            raise ValueError(
                f"option 'graph_memory_mb' must be positive, got {self.graph_memory_mb}"
            )
        if self.batch_particles < 1:
            raise ValueError(
                f"option 'batch_particles' must be at least 1, got {self.batch_particles}"
            )
