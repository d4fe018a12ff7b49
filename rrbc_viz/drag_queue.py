"""Latest wins: drag events from the browser, coalesced per handle and handled by one thread (`DragQueue`).

A drag is worth only its newest position. viser delivers every transform-controls message to the app on its event
loop; handling each one there (a re-evaluation, sometimes a refused pose that costs a failed inverse kinematics)
lets a backlog grow whenever messages come faster than they are handled — on a busy machine, or with a class
dragging at once — and the page then shows positions the server has not caught up with. So the gizmo callback only
records the event here and returns at once; one worker thread handles, per handle, the newest update (updates
queued behind a newer one are dropped), never dropping a drag's start or end and keeping their order. Handles take
turns, so one fast dragger cannot starve the others.

`wait_idle(timeout)` blocks until every recorded event is handled (tests; a caller that must read the settled
state). `stop()` ends the thread.
"""

from __future__ import annotations

import threading
import traceback
from collections import OrderedDict
from collections.abc import Callable

Handler = Callable[..., object]  # handler(kind, pid, position, phase, client=client)


class DragQueue:
    """Per handle a short list of pending events: consecutive updates merge into the newest one, so it holds at
    most start, update, end (per drag) — bounded whatever the message rate."""

    def __init__(self, handler: Handler, name: str = "rrbc-drags"):
        self._handler = handler
        self._name = name
        self._cond = threading.Condition()
        self._pending: OrderedDict[tuple, list] = OrderedDict()  # (kind, pid) -> [[phase, position, client], ...]
        self._busy = False
        self._stopped = False
        self._thread: threading.Thread | None = None
        self.dropped = 0  # updates superseded before they were handled (a measure of the backlog avoided)
        self.handled = 0
        self.ends = 0  # drags whose end has been handled

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
            self._cond.notify_all()
        self._start()

    def wait_idle(self, timeout: float = 10.0) -> bool:
        """Block until nothing is pending or being handled; True if that happened within `timeout` s."""
        with self._cond:
            return self._cond.wait_for(lambda: not self._pending and not self._busy, timeout)

    def stop(self) -> None:
        with self._cond:
            self._stopped = True
            self._pending.clear()
            self._cond.notify_all()

    def _start(self) -> None:
        with self._cond:
            if self._thread is None and not self._stopped:
                self._thread = threading.Thread(target=self._loop, name=self._name, daemon=True)
                self._thread.start()

    def _next(self):
        """The first handle's oldest event; the handle goes to the back of the line if it has more."""
        key, events = next(iter(self._pending.items()))
        event = events.pop(0)
        del self._pending[key]
        if events:
            self._pending[key] = events
        return key, event

    def _loop(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._pending or self._stopped)
                if self._stopped:
                    return
                (kind, pid), (phase, position, client) = self._next()
                self._busy = True
            try:
                self._handler(kind, pid, position, phase, client=client)
            except Exception:  # noqa: BLE001 - report, keep handling drags
                traceback.print_exc()
            finally:
                with self._cond:
                    self._busy = False
                    self.handled += 1
                    self.ends += phase == "end"
                    self._cond.notify_all()
