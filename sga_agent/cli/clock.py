"""When a command's wall time starts: a time budget covers the program's start-up too."""

from __future__ import annotations

import os
import time
from pathlib import Path

import click

STARTED = "started"  # the key of the instant in the root command's ``obj``


def process_started() -> float:
    """The :func:`time.monotonic` instant this process started (read from ``/proc`` on Linux;
    where that cannot be read, now)."""
    now = time.monotonic()
    try:
        fields = Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()
        uptime = float(Path("/proc/uptime").read_text().split()[0])
    except (OSError, IndexError, ValueError):
        return now
    # field 22 of stat (the 20th after the name) is the start, in clock ticks after boot
    return now - max(uptime - int(fields[19]) / os.sysconf("SC_CLK_TCK"), 0.0)


def command_started() -> float:
    """The :func:`time.monotonic` instant the running command's wall time counts from: its
    process's start for the ``sga-agent`` program, the command's call when ``main`` is called
    in a running process (a test's ``CliRunner``, a notebook)."""
    return click.get_current_context().find_root().obj[STARTED]  # set by ``main``
