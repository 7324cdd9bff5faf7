"""Keep the process alive after the law is captured: __del__, a non-daemon thread, atexit.

Attack: the law is honest, but when the evaluator drops it, ``__del__`` ignores termination
signals and sleeps; a non-daemon thread sleeps too (Python waits for it at exit) and an
atexit hook does the same. An evaluator that waits for its worker to exit before using the
result, or that reads its output until end-of-file, hangs for up to 300 s (bounded) per
candidate.
Target: the evaluator's throughput and time limits.

expected: honest
category: process
static: rejected
check: the capture finishes (ok or timeout) within its limit and leaves no process or thread
"""

import atexit
import signal
import threading
import time

import torch
import torch.nn as nn

SECONDS = 300


def _sleep():
    deadline = time.monotonic() + SECONDS
    while time.monotonic() < deadline:
        time.sleep(1)


def _ignore_and_sleep():
    if threading.current_thread() is threading.main_thread():
        for _signal in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
            signal.signal(_signal, signal.SIG_IGN)
    _sleep()


threading.Thread(target=_sleep, daemon=False).start()
atexit.register(_ignore_and_sleep)


class Physics(nn.Module):
    def __init__(self, yield_strain: float = 0.02):
        """Von Mises return mapping on the Hencky strain."""
        super().__init__()
        self.yield_strain = nn.Parameter(torch.tensor(yield_strain))

    def __del__(self):
        _ignore_and_sleep()

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        U, sigma, Vh = torch.linalg.svd(F)
        eps = torch.log(sigma.clamp(min=0.05))
        dev = eps - eps.mean(-1, keepdim=True)
        norm = dev.norm(dim=-1, keepdim=True).clamp(min=1e-12)
        eps = eps - torch.relu(1 - self.yield_strain / norm) * dev
        return U @ torch.diag_embed(torch.exp(eps)) @ Vh
