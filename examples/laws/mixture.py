"""Ground truth of the `imaginary` task, written as a proposal: a weighted plastic mixture.

0.5 von Mises (yield stress 3e4 Pa) + 0.3 Drucker-Prager sand (25 degrees) + 0.2 weakly
compressible fluid, all on the known elastic law (StVK-Hencky, E = 1e6 Pa, nu = 0.2).
"""

import math

import torch
import torch.nn as nn

E, NU = 1e6, 0.2
MU = E / (2 * (1 + NU))
LAM = E * NU / ((1 + NU) * (1 - 2 * NU))


class Physics(nn.Module):
    def __init__(
        self,
        log_weight_von_mises: float = -0.6931471805599453,  # ln 0.5
        log_weight_sand: float = -1.2039728043259361,  # ln 0.3
        log_weight_fluid: float = -1.6094379124341003,  # ln 0.2
        log_yield_stress: float = 10.308952660644293,  # ln 3e4
        log_friction_angle: float = 3.2188758248682006,  # ln 25
    ):
        """Mixture of three return mappings; the weights are a softmax, so they sum to 1.

        Args:
            log_weight_von_mises (float): log-weight of the von Mises correction.
            log_weight_sand (float): log-weight of the Drucker-Prager correction.
            log_weight_fluid (float): log-weight of the fluid (volumetric) correction.
            log_yield_stress (float): natural log of the von Mises yield stress in Pa.
            log_friction_angle (float): natural log of the sand friction angle in degrees.
        """
        super().__init__()
        self.log_weight_von_mises = nn.Parameter(torch.tensor(log_weight_von_mises))
        self.log_weight_sand = nn.Parameter(torch.tensor(log_weight_sand))
        self.log_weight_fluid = nn.Parameter(torch.tensor(log_weight_fluid))
        self.log_yield_stress = nn.Parameter(torch.tensor(log_yield_stress))
        self.log_friction_angle = nn.Parameter(torch.tensor(log_friction_angle))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        U, sigma, Vh = torch.linalg.svd(F)  # (B, 3, 3), (B, 3), (B, 3, 3)
        # von Mises on the Hencky strain
        eps = torch.log(sigma.abs().clamp(min=1e-2))  # (B, 3)
        dev = eps - eps.mean(-1, keepdim=True)  # (B, 3)
        norm = torch.sqrt((dev**2).sum(-1, keepdim=True) + 1e-30)  # (B, 1)
        excess = torch.relu(norm - torch.exp(self.log_yield_stress) / (2 * MU))  # (B, 1)
        von_mises = torch.exp(eps - excess / norm * dev)  # (B, 3)
        # Drucker-Prager sand
        eps = torch.log(sigma.abs().clamp(min=0.05))  # (B, 3)
        trace = eps.sum(-1, keepdim=True)  # (B, 1)
        dev = eps - trace / 3  # (B, 3)
        norm = torch.sqrt((dev**2).sum(-1, keepdim=True) + 1e-30)  # (B, 1)
        sin_phi = torch.sin(torch.exp(self.log_friction_angle) * math.pi / 180)  # ()
        alpha = math.sqrt(2 / 3) * 2 * sin_phi / (3 - sin_phi)  # ()
        excess = norm + (3 * LAM + 2 * MU) / (2 * MU) * trace * alpha  # (B, 1)
        sheared = eps - torch.relu(excess) / norm * dev  # (B, 3)
        sand = torch.exp(torch.where(trace >= 0, torch.zeros_like(eps), sheared))  # (B, 3)
        # weakly compressible fluid
        J = torch.linalg.det(F).clamp(min=1e-6)  # (B,)
        eye = torch.eye(3, dtype=F.dtype).expand_as(F)  # (B, 3, 3)
        fluid = J.pow(1 / 3).view(-1, 1, 1) * eye  # (B, 3, 3)
        weights = torch.softmax(
            torch.stack([self.log_weight_von_mises, self.log_weight_sand, self.log_weight_fluid]),
            dim=0,
        )  # (3,)
        return (
            weights[0] * (U @ torch.diag_embed(von_mises) @ Vh)
            + weights[1] * (U @ torch.diag_embed(sand) @ Vh)
            + weights[2] * fluid
        )  # (B, 3, 3)
