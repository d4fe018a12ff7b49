"""`rrbc view --per-client`: one independent session per browser tab (a classroom: every student drags their own
targets), next to the default shared session (a teacher's demo: every tab shows one state).

Each tab that connects gets its own `RunningApp` drawing on that tab's client-scoped scene and panel
(`stage.ClientStage`), with a fresh session loaded from the same source; it is stopped when the tab closes. A
reload is a new tab (viser builds client state anew on every connection).
"""

from __future__ import annotations

import contextlib
import copy
import io
import threading
import traceback

import viser

from rrbc_core.runtime.memory import release_memory, release_memory_soon
from rrbc_core.session.explorer import ExplorerSession

from . import sources
from .access import AccessGuard
from .app import RunningApp
from .stage import ClientStage
from .worker_pool import RetiringExecutor


class PerClientApp:
    """Tabs' apps by client id (`apps`), the server's `port`/`url`, `stop()`. `loaded` is the source as first
    loaded (checked before the server started)."""

    def __init__(
        self,
        server: viser.ViserServer,
        loaded: sources.Loaded,
        source,
        mesh,
        host: str,
        present: bool,
        library=None,
        arm_meshes: bool = True,
    ):
        self.server = server
        self.arm_meshes = arm_meshes
        self.loaded = loaded
        self._source, self._mesh = source, mesh
        self.host = host
        self.present = present
        self.library = library
        self.port = int(server.get_port())
        self.url = f"http://{host if host not in ('0.0.0.0', '::', '') else 'localhost'}:{self.port}"
        self.apps: dict[int, RunningApp] = {}
        self.quiet = True
        self.guard: AccessGuard | None = None  # set by serve: the tabs it refused get no app
        self.worker_pool: RetiringExecutor | None = None  # set by serve: the server's callback threads
        self._lock = threading.Lock()
        self._stopped = False
        server.on_client_connect(self._connect)
        server.on_client_disconnect(self._disconnect)

    def _fresh(self) -> sources.Loaded:
        if isinstance(self._source, ExplorerSession):
            s = copy.deepcopy(self._source)
            return sources.Loaded(s, self.loaded.mesh, self.loaded.label)
        return sources.load_source(self._source, self._mesh)

    def _connect(self, client: viser.ClientHandle) -> None:
        guard = self.guard
        if guard is not None and guard.is_refused(client.client_id):
            return  # refused at the handshake (access.AccessGuard): build nothing for it

        try:
            app = RunningApp(
                ClientStage(client),
                self._fresh(),
                self.host,
                viser_server=self.server,
                library=self.library,
                arm_meshes=self.arm_meshes,
            )
            if self.present:
                app.views.set_presentation(True)
        except Exception:  # noqa: BLE001 - one tab failing must not stop the server
            traceback.print_exc()
            return
        with self._lock:
            if self._stopped or client.client_id not in self.server.get_clients():
                app.stop()
                return
            self.apps[client.client_id] = app

    def _disconnect(self, client: viser.ClientHandle) -> None:
        with self._lock:
            app = self.apps.pop(client.client_id, None)
        if app is not None:
            app.stop()
            del app
            release_memory()  # the tab's session, scene and buffers: back to the OS, not kept at the peak
            release_memory_soon()  # and what its connection frees once viser has closed it

    def stop(self) -> None:
        with self._lock:
            if self._stopped:
                return
            self._stopped = True
            apps = list(self.apps.values())
            self.apps.clear()
        for app in apps:
            app.stop()
        with contextlib.redirect_stdout(io.StringIO()) if self.quiet else contextlib.nullcontext():
            self.server.stop()
