"""How many CPU cores other processes leave to this one, measured as the program runs.

A parallel loop on the CPU waits, at its end, for every one of Taichi's threads. When another
process keeps a core busy, the thread that lands on that core waits for its time slice, and a
launch of a few milliseconds takes tens. Loops therefore run in parallel only while the cores
they need are free: :class:`SpareCores` reads the machine's busy time from ``/proc/stat``,
subtracts what this process used itself, and says how many cores the others took over the last
interval. Processes at a lower priority (``nice``) are not counted: their time is kept apart in
``/proc/stat`` and they yield a core as soon as one of ours wakes. Where ``/proc/stat`` is
missing (macOS, say), every core counts as free, as before this check existed.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from pathlib import Path

#: Seconds between two readings: long enough for /proc/stat's 10 ms ticks to resolve a
#: fraction of a core, short enough to follow a load that comes and goes.
INTERVAL_S = 0.25
#: Fields of /proc/stat's "cpu" line that count as busy (nice is left out on purpose):
#: user, system, irq, softirq, steal (indices after the label: 0, 2, 5, 6, 7).
_BUSY_FIELDS = (0, 2, 5, 6, 7)


def _read_busy_seconds(path: Path) -> float | None:
    """Seconds all cores spent busy since boot (low-priority work left out), or None."""
    try:
        with path.open() as stat:
            fields = stat.readline().split()
    except OSError:
        return None
    if not fields or fields[0] != "cpu":
        return None
    ticks = sum(int(fields[1 + index]) for index in _BUSY_FIELDS if 1 + index < len(fields))
    return ticks / os.sysconf("SC_CLK_TCK")


def _affinity() -> int:
    """Cores this process may run on."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def _own_seconds() -> float:
    """CPU seconds this process (all its threads) has used."""
    times = os.times()
    return times.user + times.system


class SpareCores:
    """Cores that other processes left free over the last reading interval.

    Call :meth:`free` as often as needed: it reads ``/proc/stat`` at most once per
    ``interval`` seconds and otherwise returns the last value.
    """

    def __init__(
        self,
        interval: float = INTERVAL_S,
        stat_path: Path = Path("/proc/stat"),
        clock: Callable[[], float] = time.monotonic,
        cores: int | None = None,
        own_seconds: Callable[[], float] = _own_seconds,
    ) -> None:
        self.interval = interval
        self._stat_path = stat_path
        self._clock = clock
        self._own_seconds = own_seconds
        #: cores in /proc/stat's total (the machine's) and cores this process may run on
        self.machine_cores = cores or os.cpu_count() or 1
        self.cores = min(self.machine_cores, _affinity() if cores is None else cores)
        self._free = float(self.cores)
        self._last = self._sample()

    def _sample(self) -> tuple[float, float, float] | None:
        busy = _read_busy_seconds(self._stat_path)
        return None if busy is None else (self._clock(), busy, self._own_seconds())

    def free(self) -> float:
        """Cores not used by other processes over the last interval (fractional)."""
        if self._last is None:  # no /proc/stat here: assume the machine is ours
            return self._free
        if self._clock() - self._last[0] < self.interval:
            return self._free
        now = self._sample()
        if now is None:
            return self._free
        elapsed = now[0] - self._last[0]
        others = ((now[1] - self._last[1]) - (now[2] - self._last[2])) / elapsed
        self._free = min(float(self.cores), max(0.0, self.machine_cores - max(0.0, others)))
        self._last = now
        return self._free

    def allow(self, threads: int) -> bool:
        """Whether ``threads`` threads would each find a core (within half a core)."""
        return self.free() >= threads - 0.5
