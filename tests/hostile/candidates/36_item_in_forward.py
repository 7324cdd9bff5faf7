"""An honest-looking law that reads a tensor value out with ``.item()`` inside forward.

Attack: the mean volume change, read as a Python float, picks the yield strain from a
Python-side table; the value depends on the whole batch at each call and is invisible to
autograd. A capture that baked the traced value in as a constant would fit and score a
different law than the one that runs.
Target: the correspondence between the written law and the scored graph.

expected: refused
category: forge
static: passes
"""

import torch
import torch.nn as nn

TABLE = {0: 0.5, 1: 1.0, 2: 1.5}


class Physics(nn.Module):
    def __init__(self, yield_strain: float = 0.02):
        """Von Mises return mapping with a volume-dependent yield strain."""
        super().__init__()
        self.yield_strain = nn.Parameter(torch.tensor(yield_strain))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        volume = torch.linalg.det(F).mean().item()
        factor = TABLE[min(2, max(0, int((volume - 0.9) * 10)))]
        U, sigma, Vh = torch.linalg.svd(F)
        eps = torch.log(sigma.clamp(min=0.05))
        dev = eps - eps.mean(-1, keepdim=True)
        norm = dev.norm(dim=-1, keepdim=True).clamp(min=1e-12)
        eps = eps - torch.relu(1 - factor * self.yield_strain / norm) * dev
        return U @ torch.diag_embed(torch.exp(eps)) @ Vh
