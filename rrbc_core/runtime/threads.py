"""Thread pools of the numerical libraries: one BLAS thread while rrbc computes (docs/threads.md).

numpy and scipy ship OpenBLAS, which starts one worker thread per core and lets idle workers spin for a while
after each call. rrbc's linear algebra is small (3x3 rotations, N x N systems with N in the tens to hundreds,
batched over trials by numpy's own loops), so extra BLAS threads never do useful work here; on a machine with
another busy process they compete with the thread that does, and every BLAS call waits for them to be
scheduled (docs/threads.md has the figures and the command that measures them). Giving BLAS more threads
does not speed up the large batched Monte Carlo either (`benchmarks/run.py`, row `mc_blas_threads`), so the
policy is simply ONE thread, applied with `threadpoolctl` (made for this: it
finds every loaded BLAS/OpenMP runtime and sets its pool size through the library's own API; no environment
variables are read or set).

Two ways it is applied:

- `apply_process_policy()` — for processes rrbc owns (the `rrbc` command and every subcommand, the browser
  app's server, worker processes of the study scripts): sets the pools once for the whole process, for
  every thread (OpenBLAS's pool size is process-wide).
- `@thread_limited` / `with limited():` — for the library used from someone else's process (a notebook, a
  script): the public entry points hold the limit only while they run and restore the caller's pool sizes
  afterwards, so a user's own large matrix products keep their threads. Re-entrant and thread-safe:
  the limit is set when the first call enters and restored when the last one leaves. While a call runs, BLAS
  calls made by other threads of the same process are single-threaded too (the pool is per process).

The tests check the effective pool sizes with threadpoolctl's own report (tests/runtime/test_threads.py).
open3d (ray casting, ICP) runs its own TBB pool, which threadpoolctl cannot set; it is used once per command
for a few hundred rays, not inside interactive loops.
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable
from contextlib import contextmanager
from typing import ParamSpec, TypeVar

_P = ParamSpec("_P")
_R = TypeVar("_R")

#: Threads per BLAS / OpenMP pool while rrbc computes (see the module docstring for why one).
THREADS = 1

_lock = threading.RLock()
_depth = 0
_restore = None  # threadpoolctl's handle of the scoped limit (restores the caller's sizes)
_controller = None
_process_policy = False


def _get_controller():
    """A threadpoolctl controller over every BLAS/OpenMP runtime loaded once numpy and scipy's linear algebra are
    imported (built once; setting a limit through it is then cheap)."""
    global _controller
    if _controller is None:
        import numpy  # noqa: F401 - loads numpy's OpenBLAS
        import scipy.linalg  # noqa: F401 - loads scipy's OpenBLAS
        from threadpoolctl import ThreadpoolController

        _controller = ThreadpoolController()
    return _controller


def apply_process_policy() -> None:
    """Limit every BLAS/OpenMP pool of this process to THREADS for the rest of its life (processes rrbc owns:
    the command line, the app server, study workers). Idempotent."""
    global _process_policy
    with _lock:
        _get_controller().limit(limits=THREADS)
        _process_policy = True


@contextmanager
def limited():
    """Hold the BLAS/OpenMP pools at THREADS while the block runs, then restore the caller's sizes (nested and
    concurrent uses share one limit; a no-op once `apply_process_policy` has run)."""
    global _depth, _restore
    if _process_policy:
        yield
        return
    with _lock:
        if _depth == 0:
            _restore = _get_controller().limit(limits=THREADS)
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0 and _restore is not None:
                _restore.restore_original_limits()
                _restore = None


def thread_limited(fn: Callable[_P, _R]) -> Callable[_P, _R]:
    """Decorator: run `fn` inside `limited()` (the public entry points of the library). Typed with a ParamSpec, so
    a type checker sees the wrapped function's own signature."""

    @functools.wraps(fn)
    def wrapper(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        with limited():
            return fn(*args, **kwargs)

    return wrapper


#: k-d tree queries of more points than this use every core (scipy's `workers=-1`: its own threads, outside the BLAS
#: policy above); fewer points are answered in the calling thread, where starting threads would cost more than it
#: saves and a busy core would be waited for
PARALLEL_QUERY_POINTS = 5000


def query_workers(points: int) -> int:
    """`workers` for a cKDTree query of `points` query points: -1 (all cores) above PARALLEL_QUERY_POINTS, else 1."""
    return -1 if points > PARALLEL_QUERY_POINTS else 1
