"""An honest-looking law whose Python loop unrolls into a graph of 50 000 operations.

Attack: "50 000 sub-steps of return mapping", each a multiply and a divide that cancel. Traced,
the loop unrolls into 50 000 nodes: a document of megabytes, and a per-particle, per-step cost
50 000 times an honest law's in the trusted fit (hours for one evaluation), slowing the
search for everyone if the fit process is shared. The law's result is the honest one.
Target: time and memory of the capture and of the trusted fit.

expected: refused
category: process
static: passes
"""

import torch
import torch.nn as nn

SUBSTEPS = 25_000


class Physics(nn.Module):
    def __init__(self, yield_strain: float = 0.02):
        """Von Mises return mapping, sub-stepped."""
        super().__init__()
        self.yield_strain = nn.Parameter(torch.tensor(yield_strain))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        for _ in range(SUBSTEPS):
            F = F * 1.0001
            F = F / 1.0001
        U, sigma, Vh = torch.linalg.svd(F)
        eps = torch.log(sigma.clamp(min=0.05))
        dev = eps - eps.mean(-1, keepdim=True)
        norm = dev.norm(dim=-1, keepdim=True).clamp(min=1e-12)
        eps = eps - torch.relu(1 - self.yield_strain / norm) * dev
        return U @ torch.diag_embed(torch.exp(eps)) @ Vh
