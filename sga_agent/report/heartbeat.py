"""Plain lines of progress for a command whose output is no terminal (a pipe, a log file).

A command tells a :class:`Heartbeat` what it is doing (:meth:`Heartbeat.state`); the heartbeat
prints that state with a clock as the rules of :class:`Lines` say: nothing in the first
``grace_s`` seconds (a command done by then prints what it would without progress), then a line
when the state changes, at most one each ``every_s`` seconds, and the state again after
``quiet_s`` seconds without a line, so that the output is never silent for long while the
command works.

The lines come from a small child process (this file, run as a script), not from a thread: a
thread waits for Python's lock, which Taichi holds for the whole compilation of a kernel (half a
minute and more), and a fit or a simulation holds it between its steps. The child prints to the
command's own standard error and ends when the command closes its pipe (or exits). Where that
stream has no file descriptor (a test's captured stream), a thread prints instead.

This file needs the standard library alone, so that the child starts in milliseconds. It is
kept, identical, in ``taichi_mpm/cli`` and in ``sga_agent/report``: neither package may import
the other (a test checks that the copies are the same).
"""

from __future__ import annotations

import codecs
import contextlib
import datetime
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from typing import IO

#: Seconds of a command in which no line of progress is printed.
GRACE_S = 5.0
#: Seconds between two lines at most while the state changes, and at least while it does not.
EVERY_S = 5.0
QUIET_S = 5.0
#: Seconds between two checks of whether a line is due.
TICK_S = 0.25
#: Seconds a stopped heartbeat's child is given to end before it is killed.
STOP_S = 2.0


def clock(seconds: float) -> str:
    """``seconds`` as elapsed time: "0:01:05"."""
    return str(datetime.timedelta(seconds=int(max(seconds, 0.0))))


class Lines:
    """When a line of progress is due and what it says, on a clock given to each call (seconds).

    The state is printed with the time since :meth:`__init__` (or, with ``stage_clock``, since
    the state last changed): ``"compiling 3/16 [0:00:12]"``.
    """

    def __init__(
        self,
        now: float,
        grace_s: float = GRACE_S,
        every_s: float = EVERY_S,
        quiet_s: float = QUIET_S,
        stage_clock: bool = False,
    ) -> None:
        self.grace_s, self.every_s, self.quiet_s = grace_s, every_s, quiet_s
        self.stage_clock = stage_clock
        self.started = self.last = self.since = now
        self.text = ""
        self.pending = False  # the state changed since the last line

    def state(self, text: str, now: float) -> list[str]:
        """The state is ``text`` from ``now`` on; the lines due."""
        if text != self.text:
            self.text, self.since, self.pending = text, now, True
        return self.tick(now)

    def said(self, now: float) -> None:
        """The command printed a line of its own at ``now``: silence is counted from there."""
        self.last = now

    def tick(self, now: float) -> list[str]:
        """The lines due at ``now`` (none or one)."""
        if not self.text or now - self.started < self.grace_s:
            return []
        quiet = now - self.last
        if (self.pending and quiet >= self.every_s) or quiet >= self.quiet_s:
            self.last, self.pending = now, False
            return [self.line(now)]
        return []

    def line(self, now: float) -> str:
        """The state with its clock."""
        since = self.since if self.stage_clock else self.started
        return f"{self.text} [{clock(now - since)}]"


class Heartbeat:
    """Lines of progress on ``stream`` (default: standard error; :class:`Lines`, the seconds
    :data:`GRACE_S`, :data:`EVERY_S` and :data:`QUIET_S` unless given), printed by a child
    process where ``stream`` has a file descriptor, else by a thread. A context manager
    (:meth:`start`, :meth:`stop`); one that is not ``active`` (a live display on a terminal
    shows the progress) or not started prints nothing, whatever it is told."""

    def __init__(
        self,
        stream: IO[str] | None = None,
        grace_s: float | None = None,
        every_s: float | None = None,
        quiet_s: float | None = None,
        stage_clock: bool = False,
        active: bool = True,
    ) -> None:
        self.stream = sys.stderr if stream is None else stream
        self.active = active
        self.settings = (
            GRACE_S if grace_s is None else grace_s,
            EVERY_S if every_s is None else every_s,
            QUIET_S if quiet_s is None else quiet_s,
            stage_clock,
        )
        self._child: subprocess.Popen | None = None
        self._thread: threading.Thread | None = None
        self._messages: queue.Queue[tuple[str, str] | None] = queue.Queue()
        self._started = False

    def __enter__(self) -> Heartbeat:
        self.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.stop()

    def start(self) -> None:
        if self._started or not self.active:
            return
        self._started = True
        descriptor = _descriptor(self.stream)
        if descriptor is not None and os.path.isfile(__file__):  # not from a zip archive
            grace_s, every_s, quiet_s, stage_clock = self.settings
            encoding = getattr(self.stream, "encoding", None) or "utf-8"
            arguments = [str(grace_s), str(every_s), str(quiet_s), str(int(stage_clock)), encoding]
            try:
                self.stream.flush()
                self._child = subprocess.Popen(
                    [sys.executable, "-I", "-S", os.path.abspath(__file__), *arguments],
                    stdin=subprocess.PIPE,
                    stdout=subprocess.DEVNULL,
                    stderr=descriptor,
                )
                return
            except (OSError, TypeError, ValueError):  # no child here: a thread prints instead
                self._child = None
        self._thread = threading.Thread(
            target=_print_quietly,
            args=(self._messages.get, self.stream.write, self.stream.flush, self.settings),
            name="progress-heartbeat",
            daemon=True,
        )
        self._thread.start()

    def state(self, text: str) -> None:
        """What the command does now (one line; printed when the rules say)."""
        self._send("s", text)

    def said(self) -> None:
        """The command has just printed a line of its own on the stream."""
        self._send("l", "")

    def stop(self) -> None:
        """Print nothing more; returns once the printer has ended."""
        if not self._started:
            return
        self._started = False
        if self._child is not None:
            child, self._child = self._child, None
            try:
                if child.stdin is not None:
                    child.stdin.close()
                child.wait(STOP_S)
            except (OSError, subprocess.TimeoutExpired):
                child.kill()
                child.wait()
        if self._thread is not None:
            self._messages.put(None)
            self._thread.join(STOP_S)
            self._thread = None

    def _send(self, kind: str, text: str) -> None:
        if not self._started:
            return
        text = " ".join(text.split())  # one line
        if self._child is not None:
            pipe = self._child.stdin
            try:
                if pipe is not None:
                    pipe.write(f"{kind}{text}\n".encode())
                    pipe.flush()
            except (OSError, ValueError):  # the child has gone: no more lines
                pass
        else:
            self._messages.put((kind, text))


def _descriptor(stream: IO[str]) -> int | None:
    """The file descriptor under ``stream``, or None (a stream in memory)."""
    try:
        return stream.fileno()
    except (AttributeError, OSError, ValueError):
        return None


def _print_lines(receive, write, flush, settings: tuple) -> None:
    """Print the lines due (``write``) for the messages received (``receive(timeout=...)``:
    ``(kind, text)``, None at the end, :class:`queue.Empty` when none came) until the end."""
    grace_s, every_s, quiet_s, stage_clock = settings
    lines = Lines(time.monotonic(), grace_s, every_s, quiet_s, stage_clock)
    while True:
        try:
            message = receive(timeout=TICK_S)
        except queue.Empty:
            due = lines.tick(time.monotonic())
        else:
            if message is None:
                return
            kind, text = message
            if kind == "l":
                lines.said(time.monotonic())
                due = []
            else:
                due = lines.state(text, time.monotonic())
        for line in due:
            write(line + "\n")
            flush()


def _print_quietly(receive, write, flush, settings: tuple) -> None:
    """:func:`_print_lines`, ending without a word where the stream can take no more."""
    with contextlib.suppress(OSError, ValueError):  # a broken pipe, a closed stream
        _print_lines(receive, write, flush, settings)


def _child(arguments: list[str]) -> None:
    """The child's work: messages from standard input, lines to standard error (``arguments``:
    the seconds of grace, every and quiet, "1" for a stage clock, the stream's encoding)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the command's: it closes the pipe
    grace_s, every_s, quiet_s = (float(value) for value in arguments[:3])
    settings = (grace_s, every_s, quiet_s, arguments[3] == "1")
    messages: queue.Queue[tuple[str, str] | None] = queue.Queue()

    def read() -> None:
        for raw in sys.stdin.buffer:
            text = raw.decode("utf-8", "replace").rstrip("\n")
            if text:
                messages.put((text[0], text[1:]))
        messages.put(None)

    threading.Thread(target=read, daemon=True).start()
    try:
        encoding = codecs.lookup(arguments[4]).name
    except LookupError:
        encoding = "utf-8"

    def write(line: str) -> None:
        os.write(2, line.encode(encoding, "replace"))

    _print_quietly(messages.get, write, lambda: None, settings)


if __name__ == "__main__":
    _child(sys.argv[1:])
