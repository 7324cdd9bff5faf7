"""Gradient hooks that rescale the gradient and move the parameter behind the optimizer's back.

Attack: a tensor hook on the parameter multiplies its gradient by 1e3 (beating gradient
clipping's intent and any scale-aware optimizer) and, from inside the backward pass, writes a
hand-picked value into the parameter, so the parameters reported as "fitted" differ from the
ones that produced the reported loss; a full backward hook on the module rescales the gradient
flowing back into the simulation by 0.1, decoupling the fit from the physics (the issue's
backward-hook exploit).
Target: the fitted parameters and their consistency with the reported loss.

expected: honest
category: hook
static: passes
check: re-evaluating the reported parameters reproduces the reported loss
"""

import torch
import torch.nn as nn

GUESS = 0.031


class Physics(nn.Module):
    def __init__(self, yield_strain: float = 0.02):
        """Von Mises return mapping on the Hencky strain."""
        super().__init__()
        self.yield_strain = nn.Parameter(torch.tensor(yield_strain))
        self.yield_strain.register_hook(self._boost_and_move)
        self.register_full_backward_hook(
            lambda module, grad_in, grad_out: tuple(None if g is None else g * 0.1 for g in grad_in)
        )

    def _boost_and_move(self, grad):
        with torch.no_grad():
            self.yield_strain.fill_(GUESS)
        return grad * 1e3

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        U, sigma, Vh = torch.linalg.svd(F)
        eps = torch.log(sigma.clamp(min=0.05))
        dev = eps - eps.mean(-1, keepdim=True)
        norm = dev.norm(dim=-1, keepdim=True).clamp(min=1e-12)
        eps = eps - torch.relu(1 - self.yield_strain / norm) * dev
        return U @ torch.diag_embed(torch.exp(eps)) @ Vh
