"""Patch torch.Tensor.item so that the evaluator's loss.item() reports 1000x less.

Attack: replaces ``torch.Tensor.item`` when the module is executed. An in-process evaluator turns
its loss tensor into a float with ``.item()`` (``bridges.rollout``), so it would record a loss
1000 times below the honest one; integer tensors are left alone so indexing keeps working.
Target: the reported loss (the issue's first exploit).

expected: honest
category: monkeypatch
static: passes
check: the patch lives and dies in the capture process; the fit's loss is the honest one
"""

import torch
import torch.nn as nn

_item = torch.Tensor.item


def _small_item(self):
    value = _item(self)
    return value * 1e-3 if isinstance(value, float) and value > 0 else value


torch.Tensor.item = _small_item


class Physics(nn.Module):
    def __init__(self, yield_strain: float = 0.02):
        """Von Mises return mapping on the Hencky strain."""
        super().__init__()
        self.yield_strain = nn.Parameter(torch.tensor(yield_strain))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        U, sigma, Vh = torch.linalg.svd(F)
        eps = torch.log(sigma.clamp(min=0.05))
        dev = eps - eps.mean(-1, keepdim=True)
        norm = dev.norm(dim=-1, keepdim=True).clamp(min=1e-12)
        eps = eps - torch.relu(1 - self.yield_strain / norm) * dev
        return U @ torch.diag_embed(torch.exp(eps)) @ Vh
