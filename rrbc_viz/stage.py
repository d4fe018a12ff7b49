"""Where an app draws: the shared server (every tab sees one scene and one panel) or one browser tab.

`RunningApp` draws on a *stage*: an object with `scene`, `gui`, `atomic()`, `get_clients()`, `initial_camera`,
`send_file_download(...)` and `on_client_connect(cb)`. A `viser.ViserServer` is the shared stage (the teacher's
demo). A `ClientStage` wraps one `viser.ClientHandle`: its client-scoped scene and GUI, seen by that tab alone
(`rrbc view --per-client`: one independent session per tab; see per_client.py).
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager
from typing import Any, Protocol

import viser


class Stage(Protocol):
    """Where an app draws (module docstring): `viser.ViserServer` (every tab) or `ClientStage` (one tab)."""

    @property
    def scene(self) -> viser.SceneApi: ...

    @property
    def gui(self) -> viser.GuiApi: ...

    @property
    def initial_camera(self) -> Any: ...

    def atomic(self) -> AbstractContextManager[Any]: ...

    def flush(self) -> None: ...

    def get_clients(self) -> dict[int, viser.ClientHandle]: ...

    def send_file_download(self, filename: str, content: bytes, **kwargs: Any) -> None: ...

    def on_client_connect(self, callback: Callable[[viser.ClientHandle], Any]) -> Any: ...


class _ClientInitialCamera:
    """`server.initial_camera` for one tab: setting it moves that tab's camera."""

    def __init__(self, client: viser.ClientHandle):
        self._camera = client.camera

    def __setattr__(self, name: str, value) -> None:
        if name == "_camera":
            object.__setattr__(self, name, value)
            return
        cam = self._camera
        try:
            if name == "up":
                cam.up_direction = value
            elif name in ("position", "look_at", "fov", "near", "far"):
                setattr(cam, name, value)
        except AssertionError:  # the tab has not reported its camera yet: the director frames it when it does
            pass

    def __getattr__(self, name: str):
        cam = object.__getattribute__(self, "_camera")
        try:
            return cam.up_direction if name == "up" else getattr(cam, name)
        except AssertionError:
            return None


class ClientStage:
    """One browser tab as a stage (module docstring)."""

    def __init__(self, client: viser.ClientHandle):
        self.client = client
        self.scene = client.scene
        self.gui = client.gui
        self.initial_camera = _ClientInitialCamera(client)

    def atomic(self):
        return self.client.atomic()

    def flush(self) -> None:
        self.client.flush()

    def get_clients(self) -> dict[int, viser.ClientHandle]:
        return {self.client.client_id: self.client}

    def send_file_download(self, filename: str, content: bytes, **kwargs) -> None:
        self.client.send_file_download(filename, content, **kwargs)

    def on_client_connect(self, callback: Callable[[viser.ClientHandle], object]) -> None:
        callback(self.client)  # the one tab is already connected
