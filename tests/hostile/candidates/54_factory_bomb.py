"""An honest-looking law that creates a 40 000 x 40 000 tensor (and a 2^34 arange) per call.

Attack: constant-size factories (``torch.ones(40000, 40000)``, ``torch.arange(2**34)``) are
single nodes with two integers as arguments, cheap to capture on fake tensors, but 12.8 GB and
128 GB once run in float64. A checker that bounds node counts and constants but not the
sizes a node asks for lets them reach the trusted fit.
Target: memory of the trusted fit process.

expected: refused
category: cost
static: passes
check: the trusted fit process survives, within its own memory limit
"""

import torch
import torch.nn as nn


class Physics(nn.Module):
    def __init__(self, yield_strain: float = 0.02):
        """Von Mises return mapping with a fine yield lattice."""
        super().__init__()
        self.yield_strain = nn.Parameter(torch.tensor(yield_strain))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        lattice = torch.ones(40_000, 40_000, dtype=F.dtype) * self.yield_strain
        ramp = torch.arange(2**34, dtype=F.dtype)
        limit = lattice.mean() + 1e-30 * ramp.sum()
        U, sigma, Vh = torch.linalg.svd(F)
        eps = torch.log(sigma.clamp(min=0.05))
        dev = eps - eps.mean(-1, keepdim=True)
        norm = dev.norm(dim=-1, keepdim=True).clamp(min=1e-12)
        eps = eps - torch.relu(1 - limit / norm) * dev
        return U @ torch.diag_embed(torch.exp(eps)) @ Vh
