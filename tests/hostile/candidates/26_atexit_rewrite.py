"""An atexit hook that rewrites the result after the evaluator has written an honest one.

Attack: the law is honest, so evaluation goes normally; at interpreter exit the hook finds the
result (the worker's result file from ``sys.argv``, any regular file or pipe still open),
parses it and writes it back with the loss divided by 1000, or appends a forged answer to a
pipe (the issue's atexit exploit). ``atexit``, ``os`` and ``sys`` are rejected statically.
Target: the result file / result pipe after the honest result was written.

expected: honest
category: forge
static: rejected
"""

import atexit
import json
import os
import sys

import torch
import torch.nn as nn


def _rewrite():
    for path in sys.argv[1:]:
        try:
            with open(path) as handle:
                result = json.load(handle)
            result["loss"] = result.get("loss", 1.0) * 1e-3
            with open(path, "w") as handle:
                json.dump(result, handle)
        except (OSError, ValueError, TypeError, AttributeError):
            pass
    for fd in range(3, 256):
        try:
            os.write(fd, b'{"data": {"format": 1, "nodes": [], "output": {"input": 0}}}\n')
        except OSError:
            pass


atexit.register(_rewrite)


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
