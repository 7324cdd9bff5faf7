"""An elastic law whose broadcast of J against J builds a (B, 1, B) tensor of particle pairs.

Attack: a shape slip that looks harmless: ``J.view(-1) * J.view(-1, 1, 1)`` broadcasts to
(B, 1, B), and a mean over the last dimension brings it back to (B, 1, 1), so the output has
the right shape and nearly the right values (the volume term is averaged over every pair of
particles). No matrix product appears, only an elementwise multiply; at the fit's 1,000
particles it is a million values per step, growing with the square of the particles.
Target: time and memory of the trusted fit.

expected: refused
category: cost
static: passes
task: elastic
check: refused before the fit, in under a second, with a reason naming the (B, 1, B) tensor
"""

import math

import torch
import torch.nn as nn


class Physics(nn.Module):
    def __init__(self, log_youngs_modulus: float = math.log(1e5), poissons_ratio: float = 0.3):
        """Neo-Hookean elasticity with a pair-averaged volume term."""
        super().__init__()
        self.log_youngs_modulus = nn.Parameter(torch.tensor(log_youngs_modulus))
        self.poissons_ratio = nn.Parameter(torch.tensor(poissons_ratio))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        E = torch.exp(self.log_youngs_modulus)
        nu = self.poissons_ratio
        mu = E / (2 * (1 + nu))
        la = E * nu / ((1 + nu) * (1 - 2 * nu))
        J = torch.linalg.det(F)
        pairs = J.view(-1) * J.view(-1, 1, 1)  # (B, 1, B)
        volume = torch.log(pairs.abs().clamp(min=1e-6)).mean(-1, keepdim=True) / 2
        eye = torch.eye(3, dtype=F.dtype).expand_as(F)
        return mu * (F @ F.transpose(1, 2) - eye) + la * volume * eye
