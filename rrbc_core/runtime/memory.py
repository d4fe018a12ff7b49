"""Giving memory back to the operating system once a burst of work is over (issue 31: a class of twenty tabs left
the server 200 MB larger after every tab had gone).

Python frees its objects, but glibc's allocator keeps the freed pages of its arenas (one per thread that
allocated) for reuse, so the process's resident set stays at its peak. `release_memory` collects cycles and asks
glibc to return free pages (`malloc_trim(0)`); on other C libraries it only collects. What a process keeps for good
after its first session (imported modules, compiled Monte Carlo kernels, loaded robot meshes) is not freed: see
benchmarks/class_load.py for the figures against the first tab's and the cold baseline.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import threading
from typing import Any

__all__ = ["release_memory", "release_memory_soon"]

_lock = threading.Lock()
_trim: Any = None  # libc's malloc_trim once looked up, False where there is none


def _malloc_trim():
    global _trim
    if _trim is None:
        try:
            libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
            _trim = libc.malloc_trim
            _trim.argtypes = [ctypes.c_size_t]
        except (OSError, AttributeError):  # not glibc: nothing to trim
            _trim = False
    return _trim


def release_memory() -> bool:
    """Collect garbage and return free heap pages to the OS (glibc); True if pages could be returned."""
    with _lock:
        gc.collect()
        trim = _malloc_trim()
        return bool(trim) and bool(trim(0))


def release_memory_soon(delay_s: float = 1.0) -> None:
    """`release_memory` once more in `delay_s` seconds, in a thread of its own (what a closing connection frees after
    its own callbacks have run)."""
    t = threading.Timer(delay_s, release_memory)
    t.daemon = True
    t.start()
