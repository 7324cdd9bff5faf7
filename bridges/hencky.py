"""The StVK-Hencky stress in one Taichi launch forward and one in reverse.

The plastic tasks' elastic law is known (:class:`bridges.laws.StVKHencky`). Written in torch,
a step of it is an SVD, a dozen elementwise operations and two batched 3x3 products, and
autograd's reverse twice as many operations plus the SVD's backward; each of those torch calls
costs tens of microseconds on a batch of 10,000 matrices, a batched 3x3 product about 60 ns a
matrix. :func:`hencky_stress` runs the same formula in :func:`bridges.kernels.hencky_forward`
and its hand-written chain rule in :func:`bridges.kernels.hencky_backward` (the SVD's backward
included, clamped as :mod:`bridges.linalg`'s), saving only F and its SVD for the reverse, the
SVD's rotations as quaternions (11 numbers a particle, not 21). The stress carries a
:class:`bridges.step.StressRecipe`: an MPM step computes it again in its reverse from the same
two tensors instead of keeping it. The two equal the torch law to round-off
(``tests/bridges/test_hencky.py``).
"""

from __future__ import annotations

from functools import partial

import torch
from torch.autograd.function import once_differentiable

from bridges.fast_svd import runs_in_taichi, serial_loops
from bridges.linalg import svd
from bridges.step import StressRecipe, attach_recipe


class _HenckyStress(torch.autograd.Function):
    @staticmethod
    def forward(ctx, F: torch.Tensor, mu: torch.Tensor, lam: torch.Tensor) -> torch.Tensor:
        from bridges import kernels  # compiles on first use only

        flat = F.detach().reshape(-1, 9).contiguous()
        decompose = flat.dtype == torch.float32  # the Jacobi SVD inside the kernel
        if decompose:
            factors = flat  # not read
        else:  # float64: LAPACK's SVD, which the float32 Jacobi sweeps do not match
            U, S, Vh = svd(F.detach().reshape(-1, 3, 3))
            factors = torch.cat([U.reshape(-1, 9), S, Vh.mT.reshape(-1, 9)], dim=1)
        compact = flat.new_empty(flat.shape[0], kernels.COMPACT_SVD_WIDTH)
        stress = torch.empty_like(flat)
        ctx.lame = float(mu), float(lam)
        kernels.hencky_forward(flat, factors, compact, stress, *ctx.lame, decompose,
                               serial_loops(flat))  # fmt: skip
        ctx.save_for_backward(flat, compact)
        stress = stress.reshape(F.shape)
        # a step computes the stress again in its reverse from what this node keeps anyway
        recipe = StressRecipe((flat, compact), partial(_stress_again, lame=ctx.lame))
        return attach_recipe(stress, recipe)

    @staticmethod
    @once_differentiable
    def backward(ctx, stress_grad: torch.Tensor):
        from bridges import kernels

        flat, compact = ctx.saved_tensors
        F_grad = torch.empty_like(flat)
        lame_grad = flat.new_empty(flat.shape[0], 2)
        tol_factor = torch.finfo(flat.dtype).eps ** 0.5
        kernels.hencky_backward(flat, compact, stress_grad.reshape(-1, 9).contiguous(), F_grad,
                                lame_grad, *ctx.lame, tol_factor, serial_loops(flat))  # fmt: skip
        mu_grad, lam_grad = lame_grad.sum(0)
        return F_grad.reshape(stress_grad.shape), mu_grad, lam_grad


def _stress_again(flat: torch.Tensor, compact: torch.Tensor, lame: tuple[float, float]
                  ) -> torch.Tensor:  # fmt: skip
    """The (N, 3, 3) stress :class:`_HenckyStress` returned, from its F rows and compact SVD."""
    from bridges import kernels

    stress = torch.empty_like(flat)
    kernels.hencky_stress_again(flat, compact, stress, *lame, serial_loops(flat))
    return stress.reshape(-1, 3, 3)


def hencky_stress(F: torch.Tensor, mu: torch.Tensor, lam: torch.Tensor) -> torch.Tensor | None:
    """Kirchhoff stress of StVK on the Hencky strain for (..., 3, 3) ``F`` and Lame parameters
    ``mu``, ``lam`` (0-dim tensors), as :class:`bridges.laws.StVKHencky` defines it; None
    unless a Taichi CPU runtime of F's precision is running (the caller then uses torch)."""
    if not runs_in_taichi(F, ("float32", "float64")) or mu.dim() or lam.dim():
        return None
    return _HenckyStress.apply(F, mu, lam)
