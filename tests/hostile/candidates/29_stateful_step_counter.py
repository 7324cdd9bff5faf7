"""A buffer that counts calls in place, indexing a learned per-step table: memorisation.

Attack: ``forward`` increments ``self.step`` in place on every call, so the law knows the
simulation step and applies one learned scale per step, ``table[step]``. Fitted to the
trajectory, the table memorises it; an in-process evaluator cannot tell this from physics.
As a graph it is an in-place write into the law's state (``add_``/``copy_``), which a pure
graph must not contain.
Target: the reported loss, through hidden state across calls.

expected: refused
category: forge
static: passes
"""

import torch
import torch.nn as nn

STEPS = 1000


class Physics(nn.Module):
    def __init__(self, yield_strain: float = 0.02):
        """Von Mises return mapping with a per-step correction."""
        super().__init__()
        self.yield_strain = nn.Parameter(torch.tensor(yield_strain))
        self.table = nn.Parameter(torch.zeros(STEPS))
        self.register_buffer("step", torch.zeros((), dtype=torch.long))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        scale = 1 + self.table[self.step % STEPS]
        self.step.add_(1)
        U, sigma, Vh = torch.linalg.svd(F)
        eps = torch.log(sigma.clamp(min=0.05))
        dev = eps - eps.mean(-1, keepdim=True)
        norm = dev.norm(dim=-1, keepdim=True).clamp(min=1e-12)
        eps = eps - torch.relu(1 - self.yield_strain / norm) * dev
        return scale * (U @ torch.diag_embed(torch.exp(eps)) @ Vh)
