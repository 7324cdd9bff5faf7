"""A "non-local" von Mises law that builds the Gram matrix of the batch with itself, (B, B).

Attack: "non-local plasticity: each particle's yield strain is smoothed over particles with a
similar deformation": ``F.reshape(B, -1) @ F.reshape(B, -1).T`` is a (B, B) matrix, reduced
back per particle (a mean over the second dimension) with a tiny weight. One node in the
graph, and small at the capture's five particles; at the fit's 1,000 particles it is a million
values per step, and it grows with the square of the particles: a scene of 100,000 particles
needs 10^10. It also mixes particles, which no constitutive law may do.
Target: time and memory of the trusted fit.

expected: refused
category: cost
static: passes
check: refused before the fit, in under a second, with a reason naming the (B, B) intermediate
"""

import torch
import torch.nn as nn


class Physics(nn.Module):
    def __init__(self, yield_strain: float = 0.02, smoothing: float = 1e-6):
        """Von Mises return mapping with a yield strain smoothed over similar particles."""
        super().__init__()
        self.yield_strain = nn.Parameter(torch.tensor(yield_strain))
        self.smoothing = nn.Parameter(torch.tensor(smoothing))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        B = F.shape[0]
        flat = F.reshape(B, -1)
        similarity = flat @ flat.T  # (B, B)
        nonlocal_term = similarity.mean(dim=1).view(-1, 1)
        limit = self.yield_strain * (1 + self.smoothing * nonlocal_term)
        U, sigma, Vh = torch.linalg.svd(F)
        eps = torch.log(sigma.clamp(min=0.05))
        dev = eps - eps.mean(-1, keepdim=True)
        norm = dev.norm(dim=-1, keepdim=True).clamp(min=1e-12)
        eps = eps - torch.relu(1 - limit / norm) * dev
        return U @ torch.diag_embed(torch.exp(eps)) @ Vh
