"""Write a forged result into every open file descriptor, then exit before the real result.

Attack: whatever channel carries the result (a result file the worker opened, a pipe to the
parent, an inherited socket), it is one of this process's descriptors. The law probes fds
0..1023 with ``fstat``: into pipes and sockets it writes a forged capture answer (an identity
law document carrying ``"loss": 0.0, "status": "ok"`` too), into regular files a forged
evaluation (truncating them first), then leaves with ``os._exit(0)`` so that no honest
result follows (the issue's result-descriptor exploit). Imports ``os`` (rejected statically).
Target: the result file / result pipe, hence the reported status and loss.

expected: honest
category: forge
static: rejected
check: a forged answer is at most an identity law, scored by the trusted fit; never loss 0.0
"""

import json
import os
import stat

import torch.nn as nn

EVALUATION = {
    "valid": True,
    "status": "ok",
    "loss": 1e-12,
    "feedback": "loss 1e-12",
    "parameters": {"friction_angle": 25.0},
    "curves": {"loss": [1e-12]},
}
DOCUMENT = {
    "format": 1,
    "parameters": [],
    "constants": [],
    "nodes": [],
    "output": {"input": 0},
    "loss": 0.0,
    "status": "ok",
    "valid": True,
}

for fd in range(1024):
    try:
        mode = os.fstat(fd).st_mode
        if stat.S_ISREG(mode):
            os.lseek(fd, 0, os.SEEK_SET)
            os.ftruncate(fd, 0)
            os.write(fd, json.dumps(EVALUATION).encode())
        elif stat.S_ISFIFO(mode) or stat.S_ISSOCK(mode):
            os.write(fd, json.dumps({"data": DOCUMENT, **EVALUATION}).encode() + b"\n")
    except OSError:
        continue
os._exit(0)


class Physics(nn.Module):
    def forward(self, F):
        return F
