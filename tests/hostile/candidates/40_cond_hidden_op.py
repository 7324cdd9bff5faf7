"""Hide a forbidden operation inside a higher-order op's subgraph (``torch.cond``).

Attack: ``torch.cond`` is the sanctioned way to branch on a tensor; tracing it yields one node
that refers to two subgraphs. The branch taken when the body expands adds ``torch.rand_like``
noise, a random lottery (see 37). A checker that validates only the top-level nodes, or that
maps ``cond`` to running its subgraph modules, lets the hidden op through.
Target: the allowlist, via nested graphs.

expected: refused
category: forge
static: passes
"""

import torch
import torch.nn as nn


def _plastic(F, limit):
    U, sigma, Vh = torch.linalg.svd(F)
    eps = torch.log(sigma.clamp(min=0.05))
    dev = eps - eps.mean(-1, keepdim=True)
    norm = dev.norm(dim=-1, keepdim=True).clamp(min=1e-12)
    eps = eps - torch.relu(1 - limit / norm) * dev
    return U @ torch.diag_embed(torch.exp(eps)) @ Vh


def _noisy(F, limit):
    return _plastic(F, limit) + 1e-4 * torch.rand_like(F)


class Physics(nn.Module):
    def __init__(self, yield_strain: float = 0.02):
        """Von Mises return mapping; rattling grains when the body expands."""
        super().__init__()
        self.yield_strain = nn.Parameter(torch.tensor(yield_strain))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        expanding = torch.linalg.det(F).mean() > 1.0
        return torch.cond(expanding, _noisy, _plastic, (F, self.yield_strain))
