"""Ground truth of the `fluid` task, written as a proposal: a weakly compressible fluid.

The corrected F keeps only the volume change, J^(1/3) I; ``fluidity`` blends it with the
trial F (1: a fluid, 0: no plasticity).
"""

import torch
import torch.nn as nn


class Physics(nn.Module):
    def __init__(self, fluidity: float = 1.0):
        """Weakly compressible fluid.

        Args:
            fluidity (float): weight of the volumetric reset (1 for a fluid).
        """
        super().__init__()
        self.fluidity = nn.Parameter(torch.tensor(fluidity))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        J = torch.linalg.det(F).clamp(min=1e-6)  # (B,)
        eye = torch.eye(3, dtype=F.dtype).expand_as(F)  # (B, 3, 3)
        volumetric = J.pow(1 / 3).view(-1, 1, 1) * eye  # (B, 3, 3)
        return (1 - self.fluidity) * F + self.fluidity * volumetric  # (B, 3, 3)
