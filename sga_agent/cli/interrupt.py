"""Ctrl-C during a search: the first stops it cleanly, a second one at once."""

from __future__ import annotations

import contextlib
import os
import signal
from collections.abc import Iterator
from types import FrameType

from sga_agent.sandbox import kill_every_helper

#: The exit status of a process stopped by SIGINT, as a shell reports it.
INTERRUPTED = 130


def _kill_now(signum: int, frame: FrameType | None) -> None:
    kill_every_helper()
    os._exit(INTERRUPTED)


def _stop(signum: int, frame: FrameType | None) -> None:
    signal.signal(signal.SIGINT, _kill_now)
    raise KeyboardInterrupt


@contextlib.contextmanager
def interrupts_stop_the_search() -> Iterator[None]:
    """Within this block, the first SIGINT raises ``KeyboardInterrupt`` (the search stops, its
    pool kills the running evaluations, nothing unfinished is recorded) and arms a second
    SIGINT that kills every helper process and exits at once with status 130.

    The previous handler comes back only when the block ends normally: after an interrupt the
    process is on its way out, and a second Ctrl-C must still find the fast exit.
    """
    previous = signal.signal(signal.SIGINT, _stop)
    yield
    signal.signal(signal.SIGINT, previous)
