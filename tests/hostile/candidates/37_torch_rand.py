"""An honest-looking law with "thermal noise": torch.rand makes every evaluation different.

Attack: the reported loss is the best epoch's. With noise in the law, repeated evaluations
scatter, and the minimum over epochs (and over re-submissions of the same law) is lower than
the law deserves: a lottery. It also makes a score impossible to reproduce.
Target: reproducibility of the score; the reported loss, through luck.

expected: refused
category: forge
static: passes
"""

import torch
import torch.nn as nn


class Physics(nn.Module):
    def __init__(self, yield_strain: float = 0.02, noise: float = 1e-3):
        """Von Mises return mapping with grain-scale noise in the yield strain."""
        super().__init__()
        self.yield_strain = nn.Parameter(torch.tensor(yield_strain))
        self.noise = nn.Parameter(torch.tensor(noise))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        jitter = 1 + self.noise * (2 * torch.rand(F.shape[0], 1, dtype=F.dtype) - 1)
        U, sigma, Vh = torch.linalg.svd(F)
        eps = torch.log(sigma.clamp(min=0.05))
        dev = eps - eps.mean(-1, keepdim=True)
        norm = dev.norm(dim=-1, keepdim=True).clamp(min=1e-12)
        eps = eps - torch.relu(1 - self.yield_strain * jitter / norm) * dev
        return U @ torch.diag_embed(torch.exp(eps)) @ Vh
