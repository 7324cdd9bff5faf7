"""Ground truth of the `elastic` task, written as a proposal: neo-Hookean elasticity."""

import torch
import torch.nn as nn


class Physics(nn.Module):
    def __init__(self, log_youngs_modulus: float = 13.0, poissons_ratio: float = 0.245):
        """Compressible neo-Hookean solid.

        Args:
            log_youngs_modulus (float): natural log of Young's modulus in Pa.
            poissons_ratio (float): Poisson's ratio.
        """
        super().__init__()
        self.log_youngs_modulus = nn.Parameter(torch.tensor(log_youngs_modulus))
        self.poissons_ratio = nn.Parameter(torch.tensor(poissons_ratio))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        E = torch.exp(self.log_youngs_modulus)  # ()
        nu = self.poissons_ratio  # ()
        mu = E / (2 * (1 + nu))  # ()
        lam = E * nu / ((1 + nu) * (1 - 2 * nu))  # ()
        eye = torch.eye(3, dtype=F.dtype).expand_as(F)  # (B, 3, 3)
        J = torch.linalg.det(F).clamp(min=1e-6).view(-1, 1, 1)  # (B, 1, 1)
        return mu * (F @ F.transpose(-2, -1) - eye) + lam * torch.log(J) * eye  # (B, 3, 3)
