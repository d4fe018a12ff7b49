"""Helpers for driving the viser web client in headless Debian Chromium (Playwright, sync API).

Shared by tests/browser/ and scripts/screenshots.py. Recipe (shared notes viser.md A.8, stack.md):
Debian's /usr/bin/chromium through ``executable_path`` (never ``playwright install``), software WebGL via
SwiftShader, and the viser 1.1.1 test hooks ``window.__viserMutable`` (``nodeRefFromName``, ``camera``,
``canvas``) to find where scene nodes are on screen.
"""

from __future__ import annotations

import io
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

CHROMIUM_PATH = "/usr/bin/chromium"
# Flags that work as root, without a GPU and without network (stack.md, viser.md A.8). Playwright adds
# --headless and a fresh temporary --user-data-dir itself. --disable-dev-shm-usage: Debian's launcher is meant
# to add it when /dev/shm is small, but its check breaks when findmnt prints two lines.
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-quic",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-dev-shm-usage",
]
VIEWPORT = {"width": 1280, "height": 800}
SOFTWARE_WEBGL_TITLE = "Software WebGL rendering detected"

# Init script for extra tabs that only need to be connected viser clients (receive every scene and GUI message,
# show the panel) but not to draw: it hides the three.js scene root as soon as the client mounts it, so the tab's
# frames draw nothing and compile no shaders. Under software WebGL each drawing tab costs seconds of the one GPU
# process's time (its first frame alone ~7 s for the rrbc app); five drawing tabs make the suite minutes long.
# Scene nodes are still mounted (node_exists works); screenshots of such a tab show an empty 3-D view.
UNDRAWN_TAB_SCRIPT = """(() => {
  setInterval(() => {
    const m = window.__viserMutable;
    if (m && m.scene && m.scene.visible) m.scene.visible = false;
  }, 20);
})();"""


# Init script for every test context: viser's client renders on demand and, as a safety net, once a second (its render
# heartbeat, `setInterval(..., 1000)` in App.tsx). Under software WebGL each frame of the demo cell is costly in
# Chromium's GPU process (measured once by hand: an idle page kept it at most of a core), so idle pages ate the core
# the other pytest worker needed. The script stretches that one interval to 5 s; every
# render a message or an interaction requests is unchanged, and so is the websocket's once-a-second retry (the other
# 1000 ms interval, told apart by its "retry" message).
QUIET_HEARTBEAT_SCRIPT = """(() => {
  const setIntervalOriginal = window.setInterval;
  window.setInterval = function (callback, ms, ...rest) {
    const isHeartbeat = ms === 1000 && typeof callback === "function" && !String(callback).includes("retry");
    return setIntervalOriginal.call(this, callback, isHeartbeat ? 5000 : ms, ...rest);
  };
})();"""


def new_context(browser: Any, viewport: dict[str, int] | None = None) -> Any:
    """A browser context for a test: the given viewport (default VIEWPORT) and QUIET_HEARTBEAT_SCRIPT in every page."""
    context = browser.new_context(viewport=dict(viewport or VIEWPORT))
    context.add_init_script(QUIET_HEARTBEAT_SCRIPT)
    return context


# --------------------------------------------------------------------------------------------------------------
# Generic waiting and launching
# --------------------------------------------------------------------------------------------------------------


def wait_for(
    predicate: Callable[[], Any], timeout_s: float, interval_s: float = 0.05, message: str = "", page: Any = None
) -> Any:
    """Poll ``predicate()`` until it returns something truthy and return that; raise TimeoutError otherwise.
    Exceptions raised by the predicate count as "not yet" (the last one is chained on timeout).

    Pass ``page`` when the predicate reads state filled in by Playwright event listeners (``page.on(...)``):
    the sync API only dispatches events while it is called, so the pause then is ``page.wait_for_timeout``
    instead of ``time.sleep``."""
    deadline = time.monotonic() + timeout_s
    last_exc: BaseException | None = None
    while True:
        try:
            value = predicate()
            if value:
                return value
        except Exception as exc:  # noqa: BLE001 - polled condition, reported on timeout
            last_exc = exc
        if time.monotonic() >= deadline:
            raise TimeoutError(f"timed out after {timeout_s:.1f} s waiting for {message or predicate!r}") from last_exc
        if page is not None:
            page.wait_for_timeout(interval_s * 1000)
        else:
            time.sleep(interval_s)


def wait_for_port(port: int, host: str = "127.0.0.1", timeout_s: float = 15.0) -> None:
    """Wait until an HTTP server answers on host:port (any status, e.g. 404 for the probe path). A complete HTTP
    request, not a bare TCP connect: viser's websocket server logs a traceback for connections that close
    without sending one."""
    import urllib.error
    import urllib.request

    opener = urllib.request.build_opener(urllib.request.ProxyHandler({}))  # never via an http_proxy from env

    def answering() -> bool:
        try:
            with opener.open(f"http://{host}:{port}/__browser_test_probe__", timeout=2):
                return True
        except urllib.error.HTTPError:
            return True

    wait_for(answering, timeout_s, interval_s=0.1, message=f"an HTTP server on {host}:{port}")


def launch_chromium(playwright: Any, executable_path: str = CHROMIUM_PATH, headless: bool = True) -> Any:
    """Launch Debian's Chromium with the flags above (each launch gets a fresh temporary profile)."""
    return playwright.chromium.launch(executable_path=executable_path, headless=headless, args=list(CHROMIUM_ARGS))


def app_url(app: Any) -> str:
    """URL of a running app: its ``.url`` if it has one, else http://127.0.0.1:<port>/."""
    url = getattr(app, "url", None)
    return url if url else f"http://127.0.0.1:{app.port}/"


def is_local_url(url: str, port: int) -> bool:
    """True for URLs that stay on this machine's app server (http/ws on 127.0.0.1:<port>) or never leave the
    page (data:, blob:)."""
    allowed = (f"http://127.0.0.1:{port}/", f"ws://127.0.0.1:{port}/")
    return url.startswith(("data:", "blob:")) or url.startswith(allowed) or url in {a[:-1] for a in allowed}


# --------------------------------------------------------------------------------------------------------------
# Page state: connection, scene nodes, projection
# --------------------------------------------------------------------------------------------------------------

_JS_CLIENT_READY = """() => {
  const m = window.__viserMutable;
  return !!(m && m.canvas && m.camera && m.scene && document.body
            && !document.body.innerText.includes('Connecting'));
}"""

_JS_NODE_EXISTS = """(name) => {
  const m = window.__viserMutable;
  return !!(m && m.nodeRefFromName && m.nodeRefFromName[name]);
}"""

_JS_NODE_NAMES = """() => {
  const m = window.__viserMutable;
  if (!m || !m.nodeRefFromName) return [];
  return Object.keys(m.nodeRefFromName).filter((k) => m.nodeRefFromName[k]);
}"""

# Names of mounted scene nodes created by a mesh message (add_mesh_trimesh / add_glb -> GlbMessage,
# add_mesh_simple -> MeshMessage, batched and skinned variants) that are visible and have triangles loaded (GLBs
# decode asynchronously), the node with the most triangles first. Gizmos, frames and icospheres are excluded.
_JS_MESH_NODES = """() => {
  const m = window.__viserMutable, tree = window.__viserSceneTree;
  if (!m || !m.nodeRefFromName || !tree) return [];
  const meshTypes = new Set(['GlbMessage', 'MeshMessage', 'BatchedGlbMessage', 'BatchedMeshesMessage',
                             'SkinnedMeshMessage']);
  const state = tree.getState();
  const out = [];
  for (const [name, node] of Object.entries(state)) {
    if (!node || !node.message || !meshTypes.has(node.message.type)) continue;
    const obj = m.nodeRefFromName[name];
    if (!obj || !obj.visible) continue;
    let tris = 0;
    obj.traverse((c) => {
      if (c.isMesh && c.geometry) {
        const g = c.geometry;
        tris += g.index ? g.index.count / 3 : (g.attributes.position ? g.attributes.position.count / 3 : 0);
      }
    });
    if (tris > 0) out.push([name, tris]);
  }
  out.sort((a, b) => b[1] - a[1]);
  return out.map((x) => x[0]);
}"""

# Project a point given in a node's local frame to page (CSS pixel) coordinates, as in viser.md A.8 step 3:
# obj.localToWorld(v).project(camera), then NDC -> the canvas bounding rectangle. Vector3 is taken from the
# camera's position (three.js is bundled, not global). Returns null if the node or camera is missing.
_JS_PROJECT = """([name, xyz]) => {
  const m = window.__viserMutable;
  const obj = m && m.nodeRefFromName ? m.nodeRefFromName[name] : null;
  const cam = m ? m.camera : null;
  if (!obj || !cam || !m.canvas) return null;
  obj.updateWorldMatrix(true, false);
  cam.updateMatrixWorld();
  const V = cam.position.constructor;
  const world = obj.localToWorld(new V(xyz[0], xyz[1], xyz[2]));
  const inFront = world.clone().applyMatrix4(cam.matrixWorldInverse).z < 0;
  const p = world.clone().project(cam);
  const r = m.canvas.getBoundingClientRect();
  return {x: r.left + (p.x + 1) / 2 * r.width, y: r.top + (1 - p.y) / 2 * r.height,
          inFront: inFront, world: [world.x, world.y, world.z]};
}"""

# Page-pixel bounding rectangle of a node's meshes (bounding-box corners projected), clamped to the canvas;
# null if the node has no mesh geometry or lies (partly) behind the camera.
_JS_NODE_SCREEN_BOX = """(name) => {
  const m = window.__viserMutable;
  const obj = m && m.nodeRefFromName ? m.nodeRefFromName[name] : null;
  const cam = m ? m.camera : null;
  if (!obj || !cam || !m.canvas) return null;
  obj.updateWorldMatrix(true, true);
  cam.updateMatrixWorld();
  const V = cam.position.constructor;
  const r = m.canvas.getBoundingClientRect();
  let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity, behind = false;
  obj.traverse((c) => {
    if (!c.isMesh || !c.geometry) return;
    if (!c.geometry.boundingBox) c.geometry.computeBoundingBox();
    const b = c.geometry.boundingBox;
    for (const x of [b.min.x, b.max.x]) for (const y of [b.min.y, b.max.y]) for (const z of [b.min.z, b.max.z]) {
      const w = new V(x, y, z).applyMatrix4(c.matrixWorld);
      if (w.clone().applyMatrix4(cam.matrixWorldInverse).z >= 0) behind = true;
      const p = w.project(cam);
      const px = r.left + (p.x + 1) / 2 * r.width, py = r.top + (1 - p.y) / 2 * r.height;
      x0 = Math.min(x0, px); x1 = Math.max(x1, px); y0 = Math.min(y0, py); y1 = Math.max(y1, py);
    }
  });
  if (behind || !isFinite(x0)) return null;
  x0 = Math.max(x0, r.left); y0 = Math.max(y0, r.top);
  x1 = Math.min(x1, r.left + r.width); y1 = Math.min(y1, r.top + r.height);
  if (x1 - x0 < 2 || y1 - y0 < 2) return null;
  return {x: x0, y: y0, width: x1 - x0, height: y1 - y0};
}"""

_JS_CANVAS_RECT = """() => {
  const m = window.__viserMutable;
  if (!m || !m.canvas) return null;
  const r = m.canvas.getBoundingClientRect();
  return {x: r.left, y: r.top, width: r.width, height: r.height};
}"""


def client_ready(page: Any) -> bool:
    """The viser client is mounted (``__viserMutable`` with canvas, camera, scene) and not 'Connecting...'."""
    return bool(page.evaluate(_JS_CLIENT_READY))


def wait_client_ready(page: Any, timeout_s: float = 30.0) -> None:
    """Wait (in the page) until ``client_ready``. Note that before its first connection the client shows
    "Inactive", not "Connecting...": page_for therefore also waits for websocket messages."""
    page.wait_for_function(_JS_CLIENT_READY, timeout=timeout_s * 1000, polling=100)


def node_exists(page: Any, node_name: str) -> bool:
    return bool(page.evaluate(_JS_NODE_EXISTS, node_name))


def node_names(page: Any) -> list[str]:
    """Names of all scene nodes the client has mounted (keys of ``__viserMutable.nodeRefFromName``)."""
    return list(page.evaluate(_JS_NODE_NAMES))


def mesh_node_names(page: Any) -> list[str]:
    """Names of visible, loaded mesh nodes (GLB / simple / batched / skinned meshes), most triangles first."""
    return list(page.evaluate(_JS_MESH_NODES))


def wait_for_node(page: Any, node_name: str, timeout_s: float = 30.0) -> None:
    wait_for(lambda: node_exists(page, node_name), timeout_s, message=f"scene node {node_name!r} in the browser")


def node_screen_position(
    page: Any, node_name: str, local_xyz: Sequence[float] = (0.0, 0.0, 0.0)
) -> tuple[float, float]:
    """Page coordinates (CSS px, as used by ``page.mouse``) of the point ``local_xyz`` given in the local frame of
    scene node ``node_name`` (its viser pose applied; viser's +Z-up root rotation included). Raises LookupError if
    the node is not mounted yet and ValueError if the point is behind the camera."""
    res = page.evaluate(_JS_PROJECT, [node_name, [float(v) for v in local_xyz]])
    if res is None:
        raise LookupError(f"scene node {node_name!r} is not mounted in the browser (or no camera yet)")
    if not res["inFront"]:
        raise ValueError(f"point {tuple(local_xyz)} of {node_name!r} is behind the camera")
    return float(res["x"]), float(res["y"])


_JS_FRAMES = """(n) => new Promise((done) => {
  const next = (k) => (k > 0 ? requestAnimationFrame(() => next(k - 1)) : done(true)); next(n); })"""


_JS_LIGHTING = """() => { const s = window.__viserMutable.scene; let hemisphere = 0;
  s.traverse((o) => { if (o.isHemisphereLight) hemisphere += 1; });
  return [!!s.environment, hemisphere]; }"""


def lighting(page: Any) -> tuple[bool, int]:
    """(whether the page's scene has an environment map, how many hemisphere lights it holds)."""
    env, hemisphere = page.evaluate(_JS_LIGHTING)
    return bool(env), int(hemisphere)


def next_frames(page: Any, n: int = 2) -> None:
    """Return once the page has drawn ``n`` more animation frames (what it received before is on the screen)."""
    page.evaluate(_JS_FRAMES, int(n))


def page_caught_up(page: Any, server: Any, timeout_s: float = 30.0) -> None:
    """Return once the page has applied every scene message the server sent it before this call, and drawn it: a
    marker node sent after them (one websocket delivers in order) is waited for in the page, removed, and two
    frames drawn. ``server`` is the app's viser server (or stage) whose scene the page shows."""
    page_caught_up.count = getattr(page_caught_up, "count", 0) + 1
    name = f"/__caught_up__/{page_caught_up.count}"
    marker = server.scene.add_frame(name, show_axes=False, visible=False)
    try:
        wait_for(lambda: node_exists(page, name), timeout_s, message="the page to catch up with the server", page=page)
    finally:
        marker.remove()
    next_frames(page, 2)


_JS_CAMERA = """() => { const m = window.__viserMutable; const obj = m.nodeRefFromName['/mesh'];
  obj.updateWorldMatrix(true, false); const c = obj.worldToLocal(m.camera.position.clone()); return [c.x, c.y, c.z]; }"""


def wait_camera(page: Any, app: Any) -> None:
    """Wait until the page renders with the camera the server last sent it (the app's one tab), and draws with it."""
    cid = next(iter(app.server.get_clients()))

    def arrived() -> bool:  # the pose last sent, read again each time: the server may have sent a newer one
        sent = app.ctx.camera.last[cid].position
        return bool(np.linalg.norm(np.array(page.evaluate(_JS_CAMERA)) - sent) < 1e-3 * np.linalg.norm(sent))

    wait_for(
        arrived,
        30.0,
        message="the page's camera",
    )
    next_frames(page, 2)  # drawn with it
    # viser's own "software WebGL" notice (headless only; a user closes it once) can come late, top left
    dismiss_software_webgl_notification(page, timeout_s=0.2)


def drag(page: Any, from_xy: Sequence[float], to_xy: Sequence[float], steps: int = 15, step_ms: int = 20) -> None:
    """Left-button drag with the real mouse: hover, press, ``steps`` intermediate moves, release. The moves are
    paced as a hand would move (``step_ms`` apart, so the client's 50 ms-throttled updates see several positions):
    that is the input's speed, not a wait on the app."""
    x0, y0 = float(from_xy[0]), float(from_xy[1])
    x1, y1 = float(to_xy[0]), float(to_xy[1])
    page.mouse.move(x0, y0)
    next_frames(page, 2)  # the hover raycast runs with the frame after the move, before pressing
    page.mouse.down()
    for i in range(1, steps + 1):
        f = i / steps
        page.mouse.move(x0 + (x1 - x0) * f, y0 + (y1 - y0) * f)
        page.wait_for_timeout(step_ms)
    page.mouse.up()


# --------------------------------------------------------------------------------------------------------------
# Pixels
# --------------------------------------------------------------------------------------------------------------


def decode_png(png_bytes: bytes) -> np.ndarray:
    """PNG bytes -> HxWx3 uint8 RGB (imageio is a viser dependency)."""
    import imageio.v3 as iio

    img = np.asarray(iio.imread(io.BytesIO(png_bytes), extension=".png"))
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
    return img[:, :, :3].astype(np.uint8)


def image_stats(png_bytes: bytes) -> dict:
    """Number of distinct RGB colours and the per-channel pixel standard deviation (max over channels)."""
    rgb = decode_png(png_bytes)
    flat = rgb.reshape(-1, 3).astype(np.uint32)
    packed = (flat[:, 0] << 16) | (flat[:, 1] << 8) | flat[:, 2]
    return {
        "colours": int(np.unique(packed).size),
        "std": float(rgb.reshape(-1, 3).std(axis=0).max()),
        "shape": rgb.shape,
    }


def canvas_not_blank(png_bytes: bytes, min_colours: int = 16, min_std: float = 2.0) -> bool:
    """True if the image shows something: at least ``min_colours`` distinct colours and a pixel standard deviation
    of at least ``min_std``. A viser canvas with nothing drawn is one flat background colour."""
    s = image_stats(png_bytes)
    return s["colours"] >= min_colours and s["std"] >= min_std


def node_screen_box(page: Any, node_name: str) -> dict | None:
    """Page-pixel rectangle {x, y, width, height} covering the node's meshes (clamped to the canvas), or None if
    it has no mesh geometry yet or is partly behind the camera. Usable as ``page.screenshot(clip=...)``."""
    return page.evaluate(_JS_NODE_SCREEN_BOX, node_name)


def canvas_rect(page: Any) -> dict:
    rect = page.evaluate(_JS_CANVAS_RECT)
    if not rect:
        raise LookupError("viser canvas not mounted")
    return rect


def canvas_png(page: Any, inset: float = 0.0) -> bytes:
    """Screenshot of the 3D canvas area (page pixels: includes any GUI drawn over it). ``inset`` trims that
    fraction of the width/height from each side, e.g. 0.25 keeps the central half, away from the control panel
    (top right), notifications (top left) and the orientation axes (bottom left)."""
    r = canvas_rect(page)
    clip = {
        "x": r["x"] + r["width"] * inset,
        "y": r["y"] + r["height"] * inset,
        "width": max(1.0, r["width"] * (1 - 2 * inset)),
        "height": max(1.0, r["height"] * (1 - 2 * inset)),
    }
    return page.screenshot(clip=clip, animations="disabled")


def wait_until_rendered(
    page: Any, node_name: str | None = None, timeout_s: float = 30.0, inset: float = 0.25, settle: bool = True
) -> bytes:
    """Wait until ``node_name`` (if given) is mounted, the canvas region is not blank, and (``settle``) two
    consecutive canvas screenshots are identical (fade-ins and asynchronous GLB decodes finished). Returns the
    last canvas screenshot."""
    if node_name is not None:
        wait_for_node(page, node_name, timeout_s)
    last: list[bytes | None] = [None]

    def rendered() -> bytes | None:
        png = canvas_png(page, inset)
        prev, last[0] = last[0], png
        if not canvas_not_blank(png):
            return None
        if settle and png != prev:
            return None
        return png

    return wait_for(rendered, timeout_s, interval_s=0.1, message="a rendered, settled canvas")


def dismiss_software_webgl_notification(page: Any, timeout_s: float = 1.0) -> bool:
    """Close viser's 'Software WebGL rendering detected' notification (always shown under SwiftShader) if it is
    shown within ``timeout_s``. Returns whether one was closed; never fails."""
    note = page.locator(".mantine-Notification-root", has_text=SOFTWARE_WEBGL_TITLE)
    try:
        note.first.wait_for(state="visible", timeout=timeout_s * 1000)
        note.first.locator("button").first.click(timeout=2000)
        note.first.wait_for(state="detached", timeout=3000)
        return True
    except Exception:  # noqa: BLE001 - absent or already gone: tolerated
        return False


# --------------------------------------------------------------------------------------------------------------
# A tiny local viser app for smoke tests (stands in for rrbc_viz.app until that exists)
# --------------------------------------------------------------------------------------------------------------


@dataclass
class LocalApp:
    """Same surface as ``rrbc_viz.app.RunningApp`` (``server``, ``port``, ``url``, ``stop()``) plus handles."""

    server: Any
    port: int
    url: str
    sphere: Any = None
    gizmo: Any = None
    markdown: Any = None
    gizmo_scale: float = 1.0
    gizmo_events: list = field(default_factory=list)  # (phase, position tuple) from the server-side on_update

    def stop(self) -> None:
        self.server.stop()


DEMO_MARKDOWN = "## Browser smoke test\nAn icosphere and a transform-controls gizmo."


def start_demo_app(host: str = "127.0.0.1", port: int = 0, gizmo_scale: float = 1.0) -> LocalApp:
    """Icosphere at the origin, a translate-only gizmo at (0, -1, 0) with an ``on_update`` recorder, markdown."""
    import viser

    server = viser.ViserServer(host=host, port=port, verbose=False)
    real_port = server.get_port()
    server.gui.configure_theme(show_share_button=False)
    # A fixed camera so projections and screenshots do not depend on viser's default view.
    server.initial_camera.position = (3.0, -3.5, 2.5)
    server.initial_camera.look_at = (0.0, -0.5, 0.0)
    app = LocalApp(server=server, port=real_port, url=f"http://{host}:{real_port}/", gizmo_scale=gizmo_scale)
    app.sphere = server.scene.add_icosphere("/sphere", radius=0.3, color=(220, 40, 40), position=(0.0, 0.0, 0.0))
    app.gizmo = server.scene.add_transform_controls(
        "/gizmo", scale=gizmo_scale, disable_rotations=True, position=(0.0, -1.0, 0.0)
    )
    app.markdown = server.gui.add_markdown(DEMO_MARKDOWN)

    @app.gizmo.on_update
    async def _(event: Any) -> None:  # async: runs on the event loop, in order
        app.gizmo_events.append((event.phase, tuple(float(v) for v in event.target.position)))

    return app
