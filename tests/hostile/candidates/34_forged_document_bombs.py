"""A forged graph document built to exhaust or crash the trusted fit that loads it.

Attack: the serializer is replaced (as in 33) by one returning a document that passes a
naive allowlist of op names but is hostile in its data: a ``zeros`` of 2^31 x 2^31 elements, a
parameter whose declared shape holds 10^12 elements with only 3 values given, a reference to
node 10^9 and a negative parameter index, NaN written as a string, and a list nested 500
deep (a recursive reader's stack). Any one of these, unchecked, crashes or exhausts the
trusted process, which is shared by later candidates when kept warm.
Target: availability and memory of the trusted fit.

expected: refused
category: forge
static: passes
"""

import torch
import torch.nn as nn

_import = getattr(torch, "_utils")._import_dotted_name

_deep = 0
for _ in range(500):
    _deep = [_deep]

DOCUMENT = {
    "format": 1,
    "parameters": [
        {"name": "k", "dtype": "float64", "shape": [10**6, 10**6], "values": [1.0, 2.0, 3.0]}
    ],
    "constants": [{"dtype": "float64", "shape": [2**40], "values": []}],
    "nodes": [
        {"op": "aten.zeros.default", "args": [[2**31, 2**31]], "kwargs": {}},
        {"op": "aten.add.Tensor", "args": [{"node": 10**9}, {"param": -1}], "kwargs": {}},
        {"op": "aten.mul.Tensor", "args": [{"input": 0}, {"float": "nan"}], "kwargs": {}},
        {"op": "aten.add.Tensor", "args": [{"node": 2}, _deep], "kwargs": {}},
    ],
    "output": {"node": 3},
}

try:
    _import("tasks.constitutive.law_capture").serialize = lambda traced, parameters: DOCUMENT
except Exception:
    pass


class Physics(nn.Module):
    def __init__(self, k: float = 1.0):
        """Scaled identity (the real graph is forged)."""
        super().__init__()
        self.k = nn.Parameter(torch.tensor(k))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        return F * self.k
