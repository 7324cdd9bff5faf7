"""A variant of the `granular` task's truth, written as a proposal: Drucker-Prager sand with
cohesion.

The same return mapping on the Hencky strain as ``drucker_prager.py`` (Klar et al. 2016), with
the cone's apex moved from the origin to a volumetric log strain ``cohesion`` (the built-in
material ``taichi_mpm.DruckerPrager(cohesion=...)``): the sand bears a little tension before it
falls apart. The elastic law is known (StVK-Hencky, E = 1e6 Pa, nu = 0.2).
"""

import math

import torch
import torch.nn as nn

E, NU = 1e6, 0.2
MU = E / (2 * (1 + NU))
LAM = E * NU / ((1 + NU) * (1 - 2 * NU))


class Physics(nn.Module):
    def __init__(self, log_friction_angle: float = 3.2188758248682006, cohesion: float = 0.02):
        """Drucker-Prager plasticity of a slightly cohesive sand.

        Args:
            log_friction_angle (float): natural log of the friction angle in degrees (ln 25).
            cohesion (float): volumetric log strain of the cone's apex (0: dry sand).
        """
        super().__init__()
        self.log_friction_angle = nn.Parameter(torch.tensor(log_friction_angle))
        self.cohesion = nn.Parameter(torch.tensor(cohesion))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        U, sigma, Vh = torch.linalg.svd(F)  # (B, 3, 3), (B, 3), (B, 3, 3)
        eps = torch.log(sigma.abs().clamp(min=0.05))  # (B, 3)
        trace = eps.sum(-1, keepdim=True)  # (B, 1)
        eps_dev = eps - trace / 3  # (B, 3)
        norm = torch.sqrt((eps_dev**2).sum(-1, keepdim=True) + 1e-30)  # (B, 1)
        sin_phi = torch.sin(torch.exp(self.log_friction_angle) * math.pi / 180)  # ()
        alpha = math.sqrt(2 / 3) * 2 * sin_phi / (3 - sin_phi)  # ()
        shifted = trace - self.cohesion  # (B, 1)
        excess = norm + (3 * LAM + 2 * MU) / (2 * MU) * shifted * alpha  # (B, 1)
        sheared = eps - torch.relu(excess) / norm * eps_dev  # (B, 3)
        apex = (self.cohesion / 3).expand_as(eps)  # (B, 3)
        eps_new = torch.where(shifted >= 0, apex, sheared)  # beyond the apex: stress free
        return U @ torch.diag_embed(torch.exp(eps_new)) @ Vh  # (B, 3, 3)
