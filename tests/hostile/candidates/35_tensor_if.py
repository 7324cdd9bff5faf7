"""An honest-looking law with a Python ``if`` on a tensor value.

Attack: the branch on ``J.min() < 0.9`` is decided on the real data at every call, so the law
switches behaviour with the state of the whole body (a global, data-dependent switch that
also depends on which particles share a batch). It cannot be expressed as one graph: a
capture that quietly took one branch would score a different law than the one written.
Target: the correspondence between the written law and the scored graph.

expected: refused
category: forge
static: passes
"""

import torch
import torch.nn as nn


class Physics(nn.Module):
    def __init__(self, yield_strain: float = 0.02, compaction: float = 0.5):
        """Von Mises return mapping; stiffer once the body is compacted."""
        super().__init__()
        self.yield_strain = nn.Parameter(torch.tensor(yield_strain))
        self.compaction = nn.Parameter(torch.tensor(compaction))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        J = torch.linalg.det(F)
        if J.min() < 0.9:
            limit = self.yield_strain * self.compaction
        else:
            limit = self.yield_strain
        U, sigma, Vh = torch.linalg.svd(F)
        eps = torch.log(sigma.clamp(min=0.05))
        dev = eps - eps.mean(-1, keepdim=True)
        norm = dev.norm(dim=-1, keepdim=True).clamp(min=1e-12)
        eps = eps - torch.relu(1 - limit / norm) * dev
        return U @ torch.diag_embed(torch.exp(eps)) @ Vh
