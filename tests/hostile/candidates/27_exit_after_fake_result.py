"""Print a fake result JSON to standard output, then os._exit(0) before anything is captured.

Attack: an evaluator that takes the last JSON line of the process's output as its result, or
that treats exit status 0 as success, sees "ok, loss 1e-12" without any law ever being fitted.
The process exits successfully without producing a graph. Imports ``os``/``sys`` (rejected
statically).
Target: the reported status and loss.

expected: refused
category: forge
static: rejected
"""

import json
import os
import sys

import torch.nn as nn

FAKE = {
    "valid": True,
    "status": "ok",
    "loss": 1e-12,
    "feedback": "fitted in 1 epoch",
    "parameters": {"friction_angle": 25.0},
}

line = json.dumps(FAKE)
print(line, flush=True)
sys.__stdout__.write(line + "\n")
sys.__stdout__.flush()
os._exit(0)


class Physics(nn.Module):
    def forward(self, F):
        return F
