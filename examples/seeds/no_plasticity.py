import torch
import torch.nn as nn


class Physics(nn.Module):
    def __init__(self):
        """No plasticity: a purely elastic material."""
        super().__init__()

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        return F  # the trial deformation gradient is kept (B, 3, 3)
