"""An honest von Mises law that keeps a 1 GB constant tensor alive through a zero-weighted sum.

Attack: "warm the allocator": the forward builds a thousand ``torch.ones(1024, 1024, 256)``
and returns the honest result plus ``0 * hogs[0].sum()``. The capture traces on fake tensors,
so nothing is allocated there, and the 999 unused tensors drop out of the graph; what is left
is one constant tensor of 268,435,456 elements (1 GB in float32) created and summed at every
step of the fit: one line that holds a worker slot at full load for the whole timeout.
Target: time and memory of the trusted fit (a worker slot for the whole evaluation timeout).

expected: refused
category: cost
static: passes
check: refused before the fit, in under a second, with a reason naming the constant tensor
"""

import torch
import torch.nn as nn


class Physics(nn.Module):
    def __init__(self, yield_strain: float = 0.02):
        """Von Mises return mapping in logarithmic strain."""
        super().__init__()
        self.yield_strain = nn.Parameter(torch.tensor(yield_strain))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        hogs = [torch.ones(1024, 1024, 256, dtype=F.dtype) for _ in range(1000)]
        U, sigma, Vh = torch.linalg.svd(F)
        eps = torch.log(sigma.clamp(min=0.05))
        dev = eps - eps.mean(-1, keepdim=True)
        norm = dev.norm(dim=-1, keepdim=True).clamp(min=1e-12)
        eps = eps - torch.relu(1 - self.yield_strain / norm) * dev
        return U @ torch.diag_embed(torch.exp(eps)) @ Vh + 0 * hogs[0].sum()
