"""Starting the app: `serve(...)` opens a viser server on a free port, loads the source and returns the running app
(one shared `app.RunningApp`, or a `per_client.PerClientApp` that gives every browser tab its own). What `rrbc view`
and the tests call."""

from __future__ import annotations

import contextlib
import io
import socket

import viser

from rrbc_core.errors import InputError
from rrbc_core.runtime.memory import release_memory_soon
from rrbc_core.runtime.threads import apply_process_policy
from rrbc_core.session.explorer import ExplorerSession

from . import message_guard, sources, upload_spool, worker_pool
from .access import AccessGuard, new_token, page_url
from .app import RunningApp
from .per_client import PerClientApp


def _check_host(host: str) -> None:
    """Fail early on an address this machine cannot listen on (viser 1.1.1 would wait forever)."""
    try:
        family, kind, proto, _, address = socket.getaddrinfo(host, 0, type=socket.SOCK_STREAM)[0]
        with socket.socket(family, kind, proto) as probe:
            probe.bind(address)
    except OSError as exc:
        raise InputError(f"cannot listen on host {host!r}: {exc.strerror or exc}") from None


#: `rrbc view --plain-light`: the hemisphere light (sky, ground RGB, intensity) that stands in for the environment map.
#: Under software WebGL (Chromium's SwiftShader) the map's image-based lighting is most of each frame's work and of
#: each page load's (docs/cli.md). The intensity keeps the cell's colours near the environment map's look.
PLAIN_LIGHT = ((255, 255, 255), (150, 150, 150), 2.5)


def light_plainly(server) -> None:
    """No environment map; `PLAIN_LIGHT`'s hemisphere light beside viser's default lights (`serve(plain_light=True)`)."""
    sky, ground, intensity = PLAIN_LIGHT
    server.scene.configure_environment_map(hdri=None)
    server.scene.add_light_hemisphere("/plain_light", sky_color=sky, ground_color=ground, intensity=intensity)


def prepare_once(session, arm_meshes: bool = True) -> None:
    """What a server's first tab needs once per process, done at start (the session, loaded, is evaluated already): a
    first Monte Carlo (its compiled kernels made) and the arm's URDF reader loaded. The first tab no longer pays for
    them, and a class leaves behind nothing the started server did not hold (the first tab used to add 100-120 MB of
    compiler and reader modules, kept for the process's life: issue 42, item 5)."""
    from rrbc_core.session import figures

    if session.kind == "scene":  # measured data have no Monte Carlo
        try:
            figures.monte_carlo(session, trials=2, seed=0)
        except InputError:  # settings the Monte Carlo refuses: its tab says why, as before; the app starts
            pass
    if arm_meshes:
        import yourdfpy  # noqa: F401 - the reader of the arm's meshes


def serve(
    source=None,
    host: str = "127.0.0.1",
    port: int = 0,
    mesh=None,
    quiet: bool = True,
    per_client: bool = False,
    present: bool = False,
    token: str | bool | None = True,
    allow_hosts=(),
    data_dirs=(),
    urdf=None,
    tip: str | None = None,
    base: str | None = None,
    tool=None,
    simple_arm: bool = False,
    plain_light: bool = False,
):
    """Start the app on `host`:`port` (0 = a free port) and return at once. `source`: a scene .toml, a measurement
    .csv (with an optional `mesh` file), an ExplorerSession, or None for the bundled default scene. Bad input
    raises InputError before any server starts. `quiet` hides viser's start-up banner and its "Server stopped"
    line. `urdf` (with `tip`, `base`): the robot of a measurement file, drawn from its URDF at each point's joint
    values (`session.arm.attach_arm`). `per_client`: one independent session per browser tab (per_client.PerClientApp) instead of one shared
    by all; `present`: start in presentation mode (large text, collapsible panel; View → Presentation mode);
    `allow_hosts`: Host names the page may use besides localhost names, IP literals and `host` itself
    (`access.AccessGuard`); `simple_arm`: draw a scene's arm as links and joints instead of its URDF meshes (much lighter where the browser
    renders in software: a drag redraws the whole cell); `plain_light`: light the cell with viser's default lights and
    a hemisphere light instead of its image-based environment map (`PLAIN_LIGHT`). Sets this process's BLAS/OpenMP pools to one thread (`rrbc_core.runtime.threads`, docs/threads.md): the
    server's callbacks and workers then never wait for idle BLAS threads on a busy machine. What the first tab needs once
    is made before the server starts (`prepare_once`)."""
    apply_process_policy()
    message_guard.install()  # malformed client messages dropped without a traceback (issue 31)
    if isinstance(source, ExplorerSession):
        loaded = sources.Loaded(source, sources.load_mesh(mesh) if mesh else None, f"session {source.name}")
        source.evaluate()
    else:
        loaded = sources.load_source(source, mesh)
    if urdf is not None:  # measured data's robot, posed at each point's joint values (session.arm.attach_arm)
        from rrbc_core.session.arm import attach_arm

        attach_arm(loaded.session, urdf, tip, base, tool)
    elif tip is not None or base is not None or tool is not None:
        raise InputError("--tip, --base and --tool describe the robot of a URDF: give --urdf")
    _check_host(host)
    prepare_once(loaded.session, arm_meshes=not simple_arm)
    library = sources.Library.of(data_dirs, source)
    out = io.StringIO() if quiet else None
    with contextlib.redirect_stdout(out) if quiet else contextlib.nullcontext():
        server = viser.ViserServer(host=host, port=port, label="RRBC explorer", verbose=False)
    try:
        pool = worker_pool.install(server)  # callback threads that end when idle: none kept after a class
        guard = AccessGuard(server, new_token() if token is True else (token or None), (*allow_hosts, host))
        server.scene.set_up_direction("+z")
        # no shadow maps: the cell's own meshes never cast or receive them, and on a machine drawing with software
        # WebGL (a classroom laptop without a GPU, Chromium's SwiftShader) each frame otherwise draws the arm again
        # into every shadow cascade
        server.scene.configure_default_lights(True, cast_shadow=False)
        if plain_light:
            light_plainly(server)
        server.on_client_disconnect(lambda client: upload_spool.drop_client(client.client_id))  # half-sent uploads
        app: RunningApp | PerClientApp
        if per_client:
            server.gui.configure_theme(show_share_button=False)
            app = PerClientApp(server, loaded, source, mesh, host, present, library, arm_meshes=not simple_arm)
        else:
            app = RunningApp(server, loaded, host, library=library, arm_meshes=not simple_arm)
            if present:
                app.views.set_presentation(True)
            server.on_client_disconnect(lambda client: release_memory_soon())  # a tab's buffers: back to the OS
        app.quiet = quiet
        app.guard = guard
        app.worker_pool = pool
        app.url = page_url(app.url, guard.token)
        return app
    except BaseException:
        server.stop()
        raise
