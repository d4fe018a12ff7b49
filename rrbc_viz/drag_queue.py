"""Latest wins: drag events from the browser, coalesced per handle and per session, and handled by one thread for
the whole server (`DragQueue`).

A drag is worth only its newest position. viser delivers every transform-controls message to the app on its event
loop; handling each one there (a re-evaluation, sometimes a refused pose that costs a failed inverse kinematics)
lets a backlog grow whenever messages come faster than they are handled — on a busy machine, or with a class
dragging at once — and the page then shows positions the server has not caught up with. So the gizmo callback only
records the event in its session's queue and returns at once; one worker thread handles, per handle, the newest
update (updates queued behind a newer one are dropped), never dropping a drag's start or end and keeping their
order. Handles take turns within a session, and sessions take turns on the thread (issue 31: with one session per
tab, twenty threads competing for two cores left whole seconds without an answer; one thread serving the sessions
in turn gives each its share and no backlog).

`wait_idle(timeout)` blocks until every event of that queue is handled (tests; a caller that must read the settled
state). `stop()` ends the queue (the thread ends when no queue is left).
"""

from __future__ import annotations

import threading
import traceback
from collections import OrderedDict
from collections.abc import Callable

Handler = Callable[..., object]  # handler(kind, pid, position, phase, client=client)


class _Scheduler:
    """The one thread that handles every queue's events, the queues taking turns (module docstring)."""

    def __init__(self):
        self.cond = threading.Condition()
        self.queues: OrderedDict[int, DragQueue] = OrderedDict()  # id(queue) -> queue, in turn order
        self.thread: threading.Thread | None = None

    def add(self, q: DragQueue) -> None:
        with self.cond:
            self.queues[id(q)] = q

    def remove(self, q: DragQueue) -> None:
        with self.cond:
            self.queues.pop(id(q), None)
            self.cond.notify_all()

    def wake(self) -> None:
        """Start the thread if needed (caller holds cond)."""
        if self.thread is None or not self.thread.is_alive():
            self.thread = threading.Thread(target=self._loop, name="rrbc-drags", daemon=True)
            self.thread.start()
        self.cond.notify_all()

    def _pick(self):
        """The next queue with an event, its event; the queue goes to the back of the line (caller holds cond)."""
        for key, q in list(self.queues.items()):
            if q._pending:
                self.queues.move_to_end(key)
                return q, q._next()
        return None, None

    def _loop(self) -> None:
        while True:
            with self.cond:
                self.cond.wait_for(lambda: not self.queues or any(q._pending for q in self.queues.values()))
                if not self.queues:
                    self.thread = None
                    return
                q, event = self._pick()
                if q is None:
                    continue
                q._busy = True
            (kind, pid), (phase, position, client) = event
            try:
                q._handler(kind, pid, position, phase, client=client)
            except Exception:  # noqa: BLE001 - report, keep handling drags
                traceback.print_exc()
            finally:
                with self.cond:
                    q._busy = False
                    q.handled += 1
                    q.ends += phase == "end"
                    self.cond.notify_all()


_SCHEDULER = _Scheduler()


def drags_waiting() -> bool:
    """Whether any session of this process has drag events waiting or being handled (background work yields to
    them: a drag is what a user watches)."""
    with _SCHEDULER.cond:
        return any(q._pending or q._busy for q in _SCHEDULER.queues.values())


class DragQueue:
    """One session's drag events: per handle a short list of pending events where consecutive updates merge into
    the newest one, so it holds at most start, update, end (per drag) — bounded whatever the message rate."""

    def __init__(self, handler: Handler, name: str = "rrbc-drags"):
        self._handler = handler
        self._name = name
        self._pending: OrderedDict[tuple, list] = OrderedDict()  # (kind, pid) -> [[phase, position, client], ...]
        self._busy = False
        self._stopped = False
        self._cond = _SCHEDULER.cond
        self.dropped = 0  # updates superseded before they were handled (a measure of the backlog avoided)
        self.handled = 0
        self.ends = 0  # drags whose end has been handled
        _SCHEDULER.add(self)

    def submit(self, kind: str, pid: str, position, phase: str, client=None) -> None:
        """Record a drag event (what the gizmo callback calls; returns at once)."""
        key = (kind, pid)
        with self._cond:
            if self._stopped:
                return
            events = self._pending.setdefault(key, [])
            if phase == "update" and events and events[-1][0] == "update":
                events[-1] = [phase, position, client]  # latest wins
                self.dropped += 1
            else:
                events.append([phase, position, client])
            _SCHEDULER.wake()

    def wait_idle(self, timeout: float = 10.0) -> bool:
        """Block until nothing of this queue is pending or being handled; True if that happened within `timeout`."""
        with self._cond:
            return self._cond.wait_for(lambda: not self._pending and not self._busy, timeout)

    def stop(self) -> None:
        with self._cond:
            self._stopped = True
            self._pending.clear()
        _SCHEDULER.remove(self)

    def _next(self):
        """The first handle's oldest event; the handle goes to the back of the line if it has more (caller holds
        the scheduler's lock)."""
        key, events = next(iter(self._pending.items()))
        event = events.pop(0)
        del self._pending[key]
        if events:
            self._pending[key] = events
        return key, event
