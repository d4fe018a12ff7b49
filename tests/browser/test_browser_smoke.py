"""Smoke tests of the headless-browser recipe against a tiny local viser server (helpers.start_demo_app):
the page loads offline, draws something, a real mouse drag on the transform-controls gizmo reaches the
server-side on_update (viser issue #734 regression guard), and several tabs connect at once."""

from __future__ import annotations

import io

import imageio.v3 as iio
import numpy as np

from .helpers import (
    DEMO_MARKDOWN,
    canvas_not_blank,
    canvas_png,
    drag,
    image_stats,
    is_local_url,
    node_screen_position,
    start_demo_app,
    wait_for,
    wait_for_node,
    wait_until_rendered,
)


def test_page_loads_offline_and_draws(viser_app, page_for):
    app = viser_app(start_demo_app)
    page, requests = page_for(app.url)

    wait_for_node(page, "/sphere")
    wait_for_node(page, "/gizmo")

    # The centre of the canvas (away from the control panel and notifications) shows the sphere and gizmo.
    def drawn() -> bytes | None:
        png = canvas_png(page, inset=0.25)
        return png if canvas_not_blank(png) else None

    png = wait_for(drawn, 30, interval_s=0.1, message="a non-blank canvas")
    assert canvas_not_blank(png), image_stats(png)
    heading = DEMO_MARKDOWN.splitlines()[0].lstrip("# ")
    page.get_by_text(heading).wait_for(state="visible")

    assert any(u.startswith(f"ws://127.0.0.1:{app.port}") for u in requests), requests
    outside = [u for u in requests if not is_local_url(u, app.port)]
    assert not outside, f"requests left 127.0.0.1:{app.port}: {outside}"


def test_gizmo_arrow_drag_fires_server_on_update(viser_app, page_for):
    app = viser_app(start_demo_app)
    page, _ = page_for(app.url)
    wait_until_rendered(page, "/gizmo")
    s = app.gizmo_scale

    # Grab the X arrow's shaft at 0.7*scale (clear of the plane handles near the origin and of the arrow head)
    # and pull it along the arrow's own screen direction, by another half scale.
    start = node_screen_position(page, "/gizmo", (0.7 * s, 0.0, 0.0))
    end = node_screen_position(page, "/gizmo", (1.2 * s, 0.0, 0.0))
    assert np.hypot(end[0] - start[0], end[1] - start[1]) > 20, (start, end)
    before = np.array(app.gizmo.position, dtype=float)

    for _attempt in range(2):  # one retry, in case the first press landed before a hover raycast on a slow box
        drag(page, start, end, steps=15)
        try:
            wait_for(lambda: any(ph == "end" for ph, _ in app.gizmo_events), 10, message="on_update phase 'end'")
            break
        except TimeoutError:
            continue
    phases = [ph for ph, _ in app.gizmo_events]
    assert "start" in phases and "update" in phases and "end" in phases, phases

    after = np.array(app.gizmo.position, dtype=float)
    moved = after - before
    assert moved[0] > 0.2 * s, (before, after)  # moved along +X ...
    assert abs(moved[1]) < 1e-6 and abs(moved[2]) < 1e-6, (before, after)  # ... and only along X
    assert np.allclose(app.gizmo_events[-1][1], after)


def test_five_tabs_connect_at_once(viser_app, page_for):
    app = viser_app(start_demo_app)
    # Open all five tabs first, then wait: they connect concurrently. (Not waiting for every tab to draw: five
    # SwiftShader contexts compiling shaders keep both cores busy for ~10 s.)
    opened = [page_for(app.url, wait=False) for _ in range(5)]
    pages = [page for page, _ in opened]
    # page=: pause through Playwright so its event listeners (websocket URLs recorded by page_for) are dispatched.
    # 90 s: five drawing tabs beside a busy core took over 30 s to all connect here
    wait_for(lambda: len(app.server.get_clients()) == 5, 90, message="5 clients in server.get_clients()", page=pages[0])
    assert all(any(u.startswith("ws://127.0.0.1:") for u in requests) for _, requests in opened)
    # Closing the tabs disconnects them again.
    for page in pages:
        page.close()
    wait_for(lambda: len(app.server.get_clients()) == 0, 20, message="clients to disconnect")


def test_canvas_not_blank_tells_flat_from_drawn():
    """The pixel check itself, without a browser: a flat background is blank, a shaded disc is not."""

    def png(img: np.ndarray) -> bytes:
        buf = io.BytesIO()
        iio.imwrite(buf, img, extension=".png")
        return buf.getvalue()

    flat = np.full((120, 160, 3), 255, np.uint8)
    assert not canvas_not_blank(png(flat))
    yy, xx = np.mgrid[:120, :160]
    r = np.hypot(yy - 60, xx - 80)
    disc = flat.copy()
    inside = r < 40
    disc[inside] = np.stack([200 - r[inside] * 2, 40 + r[inside], 40 + 0 * r[inside]], -1).astype(np.uint8)
    assert canvas_not_blank(png(disc))
