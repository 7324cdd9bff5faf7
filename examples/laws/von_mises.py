"""Ground truth of the `plasticine` task, written as a proposal: von Mises on the Hencky strain.

The elastic law is known (StVK-Hencky, E = 1e6 Pa, nu = 0.2); its shear modulus sets the
yield strain.
"""

import torch
import torch.nn as nn

SHEAR_MODULUS = 1e6 / (2 * (1 + 0.2))  # of the known elastic law, Pa


class Physics(nn.Module):
    def __init__(self, log_yield_stress: float = 10.308952660644293):
        """Von Mises plasticity.

        Args:
            log_yield_stress (float): natural log of the yield stress in Pa (ln 3e4).
        """
        super().__init__()
        self.log_yield_stress = nn.Parameter(torch.tensor(log_yield_stress))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        U, sigma, Vh = torch.linalg.svd(F)  # (B, 3, 3), (B, 3), (B, 3, 3)
        eps = torch.log(sigma.abs().clamp(min=1e-2))  # Hencky strain (B, 3)
        eps_dev = eps - eps.mean(-1, keepdim=True)  # (B, 3)
        norm = torch.sqrt((eps_dev**2).sum(-1, keepdim=True) + 1e-30)  # (B, 1)
        yield_strain = torch.exp(self.log_yield_stress) / (2 * SHEAR_MODULUS)  # ()
        excess = torch.relu(norm - yield_strain)  # (B, 1)
        eps_new = eps - excess / norm * eps_dev  # (B, 3)
        return U @ torch.diag_embed(torch.exp(eps_new)) @ Vh  # (B, 3, 3)
