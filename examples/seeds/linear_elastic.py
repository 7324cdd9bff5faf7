import torch
import torch.nn as nn


class Physics(nn.Module):
    def __init__(self, log_youngs_modulus: float = 10.0, poissons_ratio: float = 0.13):
        """Linear (small-strain) elasticity.

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
        strain = 0.5 * (F + F.transpose(-2, -1)) - eye  # (B, 3, 3)
        trace = strain.diagonal(dim1=-2, dim2=-1).sum(-1).view(-1, 1, 1)  # (B, 1, 1)
        piola = 2 * mu * strain + lam * trace * eye  # (B, 3, 3)
        return piola @ F.transpose(-2, -1)  # Kirchhoff stress (B, 3, 3)
