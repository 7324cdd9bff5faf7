"""Give memory that a process has freed back to the system (for tasks and the fit worker).

glibc's allocator keeps freed blocks of its heap for later use, so a process that held a large
autograd graph once keeps its resident size after the graph is gone: a warm fit worker sat at
the peak of its last evaluation, and a forward pass after a backward one grew the heap past
the backward's peak instead of reusing it. :func:`release_freed_memory` asks glibc to return
its free pages (``malloc_trim``); it takes about a millisecond and does nothing where the C
library is not glibc.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools


@functools.cache
def _malloc_trim():
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        return libc.malloc_trim
    except (OSError, AttributeError):  # not glibc (macOS, musl)
        return None


def release_freed_memory() -> None:
    """Return the allocator's free pages to the system (glibc only; elsewhere a no-op)."""
    trim = _malloc_trim()
    if trim is not None:
        trim(0)
