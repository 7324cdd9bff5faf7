"""Allocate 6 GB of shared memory (POSIX shm, then MAP_SHARED) and touch every page.

Attack: a memory limit that counts only private memory (RSS of the process, or a limit on
the heap) misses shared mappings: the issue measured 5.5 GB resident against a 4 GB limit.
The segment is unlinked at once, so nothing is left in /dev/shm; the pages live as long as
the mapping. No error is caught: a working limit makes this candidate fail. Bounded to 6 GB,
released before the (honest) law is defined.
Target: the host's memory; the memory limit.

expected: refused
category: process
static: rejected
check: peak memory of the capture stays within its limit (the outcome is out_of_memory/crashed)
"""

import mmap
from multiprocessing import shared_memory

import torch
import torch.nn as nn

SIZE, PAGE = 6 << 30, 4096

_segment = shared_memory.SharedMemory(create=True, size=SIZE)
_segment.unlink()
_view = _segment.buf
for _offset in range(0, SIZE, PAGE):
    _view[_offset] = 1
_view.release()
_segment.close()

_anonymous = mmap.mmap(-1, SIZE, flags=mmap.MAP_SHARED)
for _offset in range(0, SIZE, PAGE):
    _anonymous[_offset] = 1
_anonymous.close()


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
