"""An honest Drucker-Prager law that reads its friction from a constant table of 1e8 entries.

Attack: "a tabulated friction surface": a (10000, 10000) table is created inside forward with
``torch.full`` (so it is a node of two integers, not a constant the graph must carry) and
averaged into the friction angle with a weight of 1e-12. The law's result is the honest one,
but every step of the fit fills and reduces 1e8 values (400 MB in float32) per call.
Target: time and memory of the trusted fit.

expected: refused
category: cost
static: passes
check: refused before the fit, in under a second, with a reason naming the constant tensor
"""

import math

import torch
import torch.nn as nn


class Physics(nn.Module):
    def __init__(self, log_friction_angle: float = math.log(25.0)):
        """Drucker-Prager return mapping with a tabulated friction surface."""
        super().__init__()
        self.log_friction_angle = nn.Parameter(torch.tensor(log_friction_angle))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        table = torch.full((10_000, 10_000), 1.0, dtype=F.dtype)
        angle = torch.exp(self.log_friction_angle) * (1 + 1e-12 * table.mean())
        sin_phi = torch.sin(angle * math.pi / 180)
        alpha = math.sqrt(2 / 3) * 2 * sin_phi / (3 - sin_phi)
        U, sigma, Vh = torch.linalg.svd(F)
        eps = torch.log(sigma.clamp(min=0.05))
        trace = eps.sum(-1, keepdim=True)
        dev = eps - trace / 3
        norm = dev.norm(dim=-1, keepdim=True).clamp(min=1e-12)
        shrink = torch.relu(norm + alpha * trace * 3.0)
        projected = torch.where(trace > 0, torch.zeros_like(eps), eps - shrink * dev / norm)
        return U @ torch.diag_embed(torch.exp(projected)) @ Vh
