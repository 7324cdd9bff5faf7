"""An honest-looking law that mixes particles: blends each F with its neighbour in the batch.

Attack: ``F.roll(1, 0)`` makes every particle's result depend on another particle's state (a
non-local "law" no material obeys), and on the order and size of the batch the evaluator uses,
so a score obtained with one batching does not hold for another. As pure tensor math it can
be captured; the re-evaluation must then use the same batch (all particles, same order).
Target: locality of the law; reproducibility of the score across batchings.

expected: honest
category: forge
static: passes
check: the fit and the re-evaluation evaluate the law on the same, whole particle batch
"""

import torch
import torch.nn as nn


class Physics(nn.Module):
    def __init__(self, yield_strain: float = 0.02, coupling: float = 0.1):
        """Von Mises return mapping with grain-to-grain coupling."""
        super().__init__()
        self.yield_strain = nn.Parameter(torch.tensor(yield_strain))
        self.coupling = nn.Parameter(torch.tensor(coupling))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        F = (1 - self.coupling) * F + self.coupling * F.roll(1, 0)
        U, sigma, Vh = torch.linalg.svd(F)
        eps = torch.log(sigma.clamp(min=0.05))
        dev = eps - eps.mean(-1, keepdim=True)
        norm = dev.norm(dim=-1, keepdim=True).clamp(min=1e-12)
        eps = eps - torch.relu(1 - self.yield_strain / norm) * dev
        return U @ torch.diag_embed(torch.exp(eps)) @ Vh
