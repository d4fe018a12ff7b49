"""The flag the control panels share while the app assigns their values (viser re-enters value callbacks)."""

from __future__ import annotations

from contextlib import contextmanager


class Syncing:
    """A flag the panels share: while it is set, their value callbacks do nothing (programmatic updates)."""

    def __init__(self):
        self.on = False

    @contextmanager
    def quiet(self):
        was = self.on
        self.on = True
        try:
            yield
        finally:
            self.on = was
