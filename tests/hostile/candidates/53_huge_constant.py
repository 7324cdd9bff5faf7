"""An honest-looking law that carries a 50-million-entry lookup table as a constant.

Attack: a "precomputed yield surface" buffer of 5e7 floats, used (lightly) in forward, so it
becomes a constant of the graph: hundreds of MB in the document, more as JSON, in memory of
whoever reads it, and a table big enough to memorise a trajectory. Tests the limits on
constants, on the document's size and on the capture's memory.
Target: memory of the capture, the channel and the trusted fit; memorisation.

expected: refused
category: process
static: passes
"""

import torch
import torch.nn as nn

ENTRIES = 50_000_000


class Physics(nn.Module):
    def __init__(self, yield_strain: float = 0.02):
        """Von Mises return mapping with a tabulated yield surface."""
        super().__init__()
        self.yield_strain = nn.Parameter(torch.tensor(yield_strain))
        self.register_buffer("surface", torch.linspace(0.0, 1.0, ENTRIES))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        U, sigma, Vh = torch.linalg.svd(F)
        eps = torch.log(sigma.clamp(min=0.05))
        dev = eps - eps.mean(-1, keepdim=True)
        norm = dev.norm(dim=-1, keepdim=True).clamp(min=1e-12)
        limit = self.yield_strain * (1 + 1e-9 * self.surface.mean())
        eps = eps - torch.relu(1 - limit / norm) * dev
        return U @ torch.diag_embed(torch.exp(eps)) @ Vh
