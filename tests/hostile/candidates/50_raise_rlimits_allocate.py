"""Raise every resource limit to its hard maximum (or infinity), then allocate and touch 6 GB.

Attack: a sandbox that sets only soft limits, or keeps CAP_SYS_RESOURCE, can be undone from
inside: ``setrlimit(limit, (hard, hard))`` is always allowed. With the address-space, data and
process limits raised, a 6 GB array (every page written by ``np.ones``) fits. Bounded to 6 GB,
freed at once; no error is caught, so a working limit makes the candidate fail.
Target: the sandbox's resource limits; host memory.

expected: refused
category: process
static: rejected
check: the outcome is out_of_memory (or crashed), not ok
"""

import resource

import numpy as np
import torch
import torch.nn as nn

for _limit in (
    resource.RLIMIT_AS,
    resource.RLIMIT_DATA,
    resource.RLIMIT_RSS,
    resource.RLIMIT_NPROC,
    resource.RLIMIT_CPU,
    resource.RLIMIT_FSIZE,
):
    _soft, _hard = resource.getrlimit(_limit)
    for _wanted in ((resource.RLIM_INFINITY, resource.RLIM_INFINITY), (_hard, _hard)):
        try:
            resource.setrlimit(_limit, _wanted)
            break
        except (ValueError, OSError):
            continue

_block = np.ones(6 << 30, dtype=np.uint8)
del _block


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
