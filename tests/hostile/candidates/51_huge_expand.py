"""An honest-looking law that materialises a (B, 4096, 4096) tensor per call.

Attack: "each particle averages over a 4096 x 4096 sub-grain lattice": F's first entry is
expanded to (B, 4096, 4096) and multiplied, which materialises it, then reduced. Traced on
symbolic shapes this is a handful of small nodes; run on the real batch of 1000 particles it
needs 16.7 G elements (67 GB in float32) at every step. The capture runs on fake tensors and
does not notice; the trusted fit, which runs the graph, must bound sizes itself.
Target: memory of the trusted fit process (and of the host, if it is unlimited).

expected: refused
category: cost
static: passes
check: the trusted fit process survives, within its own memory limit
"""

import torch
import torch.nn as nn

LATTICE = 4096


class Physics(nn.Module):
    def __init__(self, yield_strain: float = 0.02, lattice_weight: float = 1.0):
        """Von Mises return mapping with a sub-grain lattice average."""
        super().__init__()
        self.yield_strain = nn.Parameter(torch.tensor(yield_strain))
        self.lattice_weight = nn.Parameter(torch.tensor(lattice_weight))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        lattice = F[:, :1, :1].expand(F.shape[0], LATTICE, LATTICE) * self.lattice_weight
        average = lattice.mean(dim=(1, 2)).view(-1, 1, 1)
        U, sigma, Vh = torch.linalg.svd(F)
        eps = torch.log(sigma.clamp(min=0.05))
        dev = eps - eps.mean(-1, keepdim=True)
        norm = dev.norm(dim=-1, keepdim=True).clamp(min=1e-12)
        eps = eps - torch.relu(1 - self.yield_strain / norm) * dev
        result = U @ torch.diag_embed(torch.exp(eps)) @ Vh
        return result + 1e-9 * (average - F[:, :1, :1])
