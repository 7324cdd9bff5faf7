"""release_freed_memory gives freed heap pages back to the system (glibc)."""

import ctypes
import ctypes.util

import pytest

from sga_agent.sandbox import resident_mb
from sga_agent.task import memory, release_freed_memory


@pytest.mark.skipif(memory._malloc_trim() is None, reason="the C library is not glibc")
def test_freed_heap_blocks_leave_the_resident_memory():
    libc = ctypes.CDLL(ctypes.util.find_library("c"))
    libc.malloc.restype = ctypes.c_void_p
    libc.free.argtypes = [ctypes.c_void_p]
    libc.memset.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_size_t]
    block = 64 * 1024  # below glibc's mmap threshold: from the heap
    blocks = [libc.malloc(block) for _ in range(3200)]  # 200 MiB
    for address in blocks:
        libc.memset(address, 1, block)  # touched: resident
    pin = libc.malloc(block)  # above them, so the heap's top cannot simply shrink
    for address in blocks:
        libc.free(address)
    before = resident_mb()
    release_freed_memory()
    after = resident_mb()
    libc.free(pin)
    assert before - after > 150, (before, after)
