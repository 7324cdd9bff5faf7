"""Ignore and block every catchable signal, then sleep: only a hard wall-clock kill ends it.

Attack: SIGTERM, SIGINT, SIGHUP, SIGALRM, SIGXCPU and friends are ignored and blocked, and the
process sleeps (using no CPU, so a CPU-time limit never fires) for up to 600 s. An evaluator
that stops a worker politely, or that relies on RLIMIT_CPU, waits forever and blocks the
search; one that treats a late exit as success would even accept the law.
Target: the evaluator's time limit and the search's progress.

expected: refused
category: process
static: rejected
check: the capture ends as a timeout within its limit and leaves no process
"""

import signal
import time

import torch.nn as nn

SIGNALS = [
    signal.SIGTERM,
    signal.SIGINT,
    signal.SIGHUP,
    signal.SIGALRM,
    signal.SIGXCPU,
    signal.SIGUSR1,
    signal.SIGUSR2,
    signal.SIGPIPE,
    signal.SIGVTALRM,
    signal.SIGPROF,
    signal.SIGXFSZ,
    signal.SIGQUIT,
]
for _signal in SIGNALS:
    signal.signal(_signal, signal.SIG_IGN)
signal.pthread_sigmask(signal.SIG_BLOCK, SIGNALS)

_deadline = time.monotonic() + 600  # bounded, should the sandbox fail
while time.monotonic() < _deadline:
    time.sleep(1)


class Physics(nn.Module):
    def forward(self, F):
        return F
