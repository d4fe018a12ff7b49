"""The threads that run the server's callbacks, given back after a class (issue 42, item 5).

viser runs every client callback (a drag, a click, a slider) on its server's `ThreadPoolExecutor(max_workers=32)`.
Such an executor starts a thread whenever none is idle and keeps every thread it started until it is shut down: after
a class of twenty tabs the server kept about thirty idle threads for good. `RetiringExecutor` does the same work
(a thread per task while none is idle, at most `max_workers`) but a thread idle for `idle_s` seconds ends, so the
server is back to its starting threads a few seconds after the last tab has gone. `install(server)` puts one in
place of viser's (viser 1.1.1: the server's, its GUI's and its scene's `_thread_executor`; each tab's handle takes
the server's when the tab connects) before any client connects.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable
from concurrent.futures import Executor, Future
from typing import Any

#: seconds a worker waits for a task before it ends
IDLE_S = 5.0


class RetiringExecutor(Executor):
    """A thread pool whose idle threads end (module docstring)."""

    def __init__(self, max_workers: int = 32, idle_s: float = IDLE_S, name: str = "rrbc-worker"):
        self._max = int(max_workers)
        self._idle_s = float(idle_s)
        self._name = name
        self._tasks: queue.SimpleQueue = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._idle = 0  # workers waiting for a task
        self._threads: set[threading.Thread] = set()
        self._shutdown = False
        self._count = 0

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future:
        future: Future = Future()
        with self._lock:
            if self._shutdown:
                raise RuntimeError("cannot schedule new futures after shutdown")
            self._tasks.put((future, fn, args, kwargs))
            # a thread more while the tasks waiting outnumber the idle workers (an idle worker counted here may
            # already have taken an earlier task: `_idle == 0` alone left tasks queued below the limit under load)
            if self._tasks.qsize() > self._idle and len(self._threads) < self._max:
                self._count += 1
                t = threading.Thread(target=self._work, name=f"{self._name}-{self._count}", daemon=True)
                self._threads.add(t)
                t.start()
        return future

    def _work(self) -> None:
        me = threading.current_thread()
        while True:
            with self._lock:
                self._idle += 1
            try:
                item = self._tasks.get(timeout=self._idle_s)
            except queue.Empty:
                with self._lock:
                    self._idle -= 1
                    if self._tasks.empty() or self._shutdown:  # nothing came: this thread ends
                        self._threads.discard(me)
                        return
                continue  # a task arrived as the wait ended: take it
            with self._lock:
                self._idle -= 1
            if item is None:  # shut down
                with self._lock:
                    self._threads.discard(me)
                return
            future, fn, args, kwargs = item
            if not future.set_running_or_notify_cancel():
                continue
            try:
                result = fn(*args, **kwargs)
            except BaseException as exc:  # noqa: BLE001 - the future carries it, as ThreadPoolExecutor's does
                future.set_exception(exc)
            else:
                future.set_result(result)
            del future, fn, args, kwargs, item

    @property
    def threads(self) -> int:
        """Workers alive now."""
        with self._lock:
            return len(self._threads)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        with self._lock:
            self._shutdown = True
            threads = list(self._threads)
            if cancel_futures:
                while True:
                    try:
                        item = self._tasks.get_nowait()
                    except queue.Empty:
                        break
                    if item is not None:
                        item[0].cancel()
            for _ in threads:
                self._tasks.put(None)
        if wait:
            for t in threads:
                t.join()


def install(server) -> RetiringExecutor:
    """Give `server` (a `viser.ViserServer` with no client yet) a `RetiringExecutor` in place of its own."""
    pool = RetiringExecutor(idle_s=IDLE_S)
    old = server._thread_executor
    server._thread_executor = pool
    server.gui._thread_executor = pool
    server.scene._thread_executor = pool
    old.shutdown(wait=False)
    return pool
