"""The real app (`rrbc_viz.serve.serve()` on the bundled default scene) in headless Chromium, as a user sees it:
the page loads offline and draws the cell, and ticking the heat map changes the 3-D view at the default camera,
in the legend's colours; a real mouse drag of a target's arrow changes the numbers the page shows (and the
server's session), far enough marks the target extrapolated; bad files loaded from the File tab give a visible
error while the server keeps serving (a later drag still works); five tabs share one state.

Numbers are read from the page (DOM text of the control panel), and compared with the server's session to check
that the page shows what the server holds. Each drawing tab costs ~10 s of software WebGL (first frame), so the
steps of a user's session share a page where they can.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import rrbc_core
from rrbc_viz import colors
from rrbc_viz.serve import serve

from .helpers import (
    UNDRAWN_TAB_SCRIPT,
    canvas_not_blank,
    decode_png,
    drag,
    image_stats,
    is_local_url,
    lighting,
    mesh_node_names,
    node_exists,
    node_screen_position,
    wait_for,
    wait_until_rendered,
)

pytestmark = pytest.mark.browser

EXAMPLE_CSV = Path(rrbc_core.__file__).resolve().parent / "data" / "example_measurements.csv"
H1_GIZMO = "/targets/H1/gizmo"

# Every row of every table in the page, as the cells' visible text.
_JS_TABLE_ROWS = """() => Array.from(document.querySelectorAll('table tr'))
  .map((tr) => Array.from(tr.cells).map((c) => c.innerText.trim()))"""


# --------------------------------------------------------------------------------------------------------------
# Reading and driving the page
# --------------------------------------------------------------------------------------------------------------


def target_row(page, pid: str) -> list[str] | None:
    """The per-target table row of `pid` as the page shows it: [id, rigid, RRBC, |ê|, (std,) hull]."""
    rows = [r for r in page.evaluate(_JS_TABLE_ROWS) if r and r[0] == pid]
    return rows[0] if rows else None


def expected_row(app, pid: str) -> list[str]:
    """The same row formatted from the server's current Evaluation (as rrbc_viz.tables does)."""
    t = app.session.last.targets
    i = list(t.ids).index(pid)
    hull = "⚠ extrapolated" if bool(t.extrapolated[i]) else "inside"
    return [
        pid,
        f"{t.error_rigid[i]:.3f}",
        f"{t.error_rrbc[i]:.3f}",
        f"{float(np.linalg.norm(t.correction[i])):.3f}",
        hull,
    ]


def server_position(app, kind: str, pid: str) -> np.ndarray:
    group = app.session.layout[kind]
    return np.array(group.positions[group.index(pid)], float)


def open_tab(page, name: str) -> None:
    page.get_by_role("tab", name=name).click()


def drag_axis(page, node: str, scale: float, from_local: float, to_local: float, steps: int = 8) -> None:
    """Real-mouse drag of the X arrow of gizmo `node`: press on the shaft at `from_local`·scale along its local
    X axis and release over `to_local`·scale (both projected with the page's camera). Eight moves: under
    software WebGL each waits for a frame of the whole cell (0.5-2 s here), and a few already send several
    updates."""
    start = node_screen_position(page, node, (from_local * scale, 0.0, 0.0))
    end = node_screen_position(page, node, (to_local * scale, 0.0, 0.0))
    assert np.hypot(end[0] - start[0], end[1] - start[1]) > 15, (start, end)
    drag(page, start, end, steps=steps)


def drag_until_moved(app, page, pid: str, from_local: float, to_local: float) -> np.ndarray:
    """Drag target `pid`'s X arrow (one retry if the press missed) until the server's target moved; returns the
    server-side displacement (mm, robot frame)."""
    before = server_position(app, "targets", pid)
    scale = app.nodes.gizmo_scale()
    for _attempt in range(2):
        drag_axis(page, f"/targets/{pid}/gizmo", scale, from_local, to_local)
        try:
            wait_for(
                lambda: not np.allclose(server_position(app, "targets", pid), before),
                10,
                message=f"{pid} to move on the server",
                page=page,
            )
            break
        except TimeoutError:
            continue
    # the drag's "end" update has been handled once the page shows the server's numbers for the final position
    wait_for(
        lambda: target_row(page, pid) == expected_row(app, pid),
        15,
        message=f"the page to show {pid}'s numbers after the drag",
        page=page,
    )
    return server_position(app, "targets", pid) - before


def notification_texts(page) -> list[str]:
    return page.locator(".mantine-Notification-root").all_inner_texts()


def _ring_colour_pixels(
    png: bytes, offset: tuple[float, float], centres: dict, colours: dict, half: int = 40, tol: int = 10
) -> dict:
    """Per target: pixels within `half` px of its screen position whose colour is within `tol` (per channel) of
    the target's expected heat-map colour."""
    img = decode_png(png).astype(int)
    out = {}
    for pid, (x, y) in centres.items():
        cx, cy = int(round(x - offset[0])), int(round(y - offset[1]))
        patch = img[max(0, cy - half) : cy + half, max(0, cx - half) : cx + half]
        out[pid] = int(np.sum(np.all(np.abs(patch - np.asarray(colours[pid], int)) <= tol, axis=2)))
    return out


def settled_shot(page, clip: dict, timeout_s: float = 20.0) -> bytes:
    """A screenshot of `clip` once two consecutive ones are identical."""

    def same():
        a = page.screenshot(clip=clip, animations="disabled")
        b = page.screenshot(clip=clip, animations="disabled")
        return a if a == b else None

    return wait_for(same, timeout_s, interval_s=0.2, message="a settled view", page=page)


# --------------------------------------------------------------------------------------------------------------
# Tests
# --------------------------------------------------------------------------------------------------------------


def test_loads_offline_draws_the_cell_and_shows_the_heat_map(viser_app, page_for):
    app = viser_app(lambda: serve(simple_arm=True, plain_light=True))
    page, requests = page_for(app.url)

    # 1) the default scene, drawn: settled and not blank (central half of the view), the mesh mounted with triangles
    png = wait_until_rendered(page, "/mesh/cell", timeout_s=60)
    assert canvas_not_blank(png), image_stats(png)
    assert node_exists(page, "/mesh/cell") and "/mesh/cell" in mesh_node_names(page)
    assert node_exists(page, H1_GIZMO) and node_exists(page, "/targets/H1/gizmo/sphere")
    page.get_by_text("Demo work cell", exact=False).first.wait_for(state="visible")
    assert target_row(page, "H1") == expected_row(app, "H1")  # the panel shows the server's numbers
    # --plain-light: no environment map, one hemisphere light (serve.PLAIN_LIGHT)
    wait_for(lambda: lighting(page) == (False, 1), 15, message="plain lighting", page=page)

    # 2) heat map: View -> tick "Heat map of predicted error". The regions are mm-sized in a metre-sized cell; the
    # 3-D view must change where the targets are, in the legend's colours (regression: it used to be identical).
    open_tab(page, "View")
    ids = list(app.session.last.targets.ids)
    centres = {pid: node_screen_position(page, f"/targets/{pid}/gizmo") for pid in ids}
    xs, ys = [c[0] for c in centres.values()], [c[1] for c in centres.values()]
    clip = {
        "x": min(xs) - 60,
        "y": min(ys) - 60,
        "width": max(xs) - min(xs) + 120,
        "height": max(ys) - min(ys) + 120,
    }  # the targets' part of the 3-D view, left of the panel
    assert clip["x"] + clip["width"] < 880, clip
    off = settled_shot(page, clip)

    page.get_by_text("Heat map of predicted error", exact=True).click()
    wait_for(
        lambda: app.state.layers.get("heatmap") and app.state.heat_map is not None,
        15,
        message="the heat map on",
        page=page,
    )
    # each target's expected colour: the mean predicted error (with RRBC) over its region, on the legend's scale
    hm = app.state.heat_map
    both = np.concatenate([hm.error_rigid, hm.error_rrbc])
    lo, hi = float(np.nanmin(both)), float(np.nanmax(both))
    owner = np.asarray(hm.target)
    colours = {pid: tuple(colors.scale_colors([hm.error_rrbc[owner == pid].mean()], lo, hi)[0]) for pid in ids}
    page.get_by_text(f"{lo:.4f} mm (low)", exact=False).first.wait_for(state="visible")  # legend in mm
    assert f"{hi:.4f} mm (high)" in page.inner_text("body")

    def shown():
        png = page.screenshot(clip=clip, animations="disabled")
        counts = _ring_colour_pixels(png, (clip["x"], clip["y"]), centres, colours)
        return (png, counts) if min(counts.values()) >= 25 else None

    on, counts = wait_for(shown, 30, interval_s=0.3, message="every target's heat-map colour in the view", page=page)
    before = _ring_colour_pixels(off, (clip["x"], clip["y"]), centres, colours)
    assert all(counts[p] >= before[p] + 25 for p in ids), (before, counts)
    a, b = decode_png(off).astype(int), decode_png(on).astype(int)
    changed = int(np.sum(np.abs(a - b).max(axis=2) > 30))
    assert changed > 1000, f"heat map on vs off: only {changed} pixels of the 3-D view differ"

    # 3) nothing left 127.0.0.1, including late requests (fonts, icons) after rendering and the tab switch
    assert any(u.startswith(f"ws://127.0.0.1:{app.port}") for u in requests), requests
    outside = [u for u in requests if not is_local_url(u, app.port)]
    assert not outside, f"requests left 127.0.0.1:{app.port}: {outside}"


def test_drag_changes_the_page_then_bad_files_fail_visibly_and_dragging_goes_on(viser_app, page_for, tmp_path):
    app = viser_app(lambda: serve(data_dirs=[tmp_path], simple_arm=True, plain_light=True))
    page, requests = page_for(app.url)
    wait_until_rendered(page, H1_GIZMO, timeout_s=60)
    scale = app.nodes.gizmo_scale()
    row0 = target_row(page, "H1")
    assert row0 == expected_row(app, "H1") and row0[-1] == "inside", row0

    # 1) pull H1's X arrow from 0.7 to 1.5 gizmo scales: +0.8 scale along robot X, still inside the hull
    moved = drag_until_moved(app, page, "H1", 0.7, 1.5)
    assert 0.5 * 0.8 * scale < moved[0] < 1.5 * 0.8 * scale, moved
    assert abs(moved[1]) < 1e-6 and abs(moved[2]) < 1e-6, moved  # only along X
    row1 = target_row(page, "H1")
    assert row1[1:4] != row0[1:4] and row1[-1] == "inside", (row0, row1)  # rigid, RRBC, |ê| changed

    # 2) pull it back past its start, 3.2 scales along -X (~175 mm): out of the fiducials' hull (x < 300 mm)
    moved = drag_until_moved(app, page, "H1", 0.7, -2.5)
    assert moved[0] < -0.5 * 3.2 * scale, moved
    assert server_position(app, "targets", "H1")[0] < 300.0
    row2 = target_row(page, "H1")
    assert "extrapolated" in row2[-1] and row2[1:4] != row1[1:4], (row1, row2)
    note = page.get_by_text("(outside the fiducials' hull):", exact=False).first  # the summary's list
    note.wait_for(state="visible")
    assert "H1" in note.inner_text()
    assert np.allclose(server_position(app, "targets", "H2"), [400.0, -50.0, 15.0])  # the others stay

    # 3) a bad scene and a bad measurement file in a folder given with --data, picked in the File tab (after a
    # rescan: they were written after the server started) and loaded with its button
    bad_scene = tmp_path / "broken_scene.toml"
    bad_scene.write_text("[scene\nname = 'missing bracket'\n", encoding="utf-8")
    lines = EXAMPLE_CSV.read_text(encoding="utf-8").splitlines()
    data = [k for k, line in enumerate(lines) if line and not line.startswith("#")]
    cells = lines[data[2]].split(",")
    cells[lines[data[0]].split(",").index("sensor_y")] = "12.x"  # one unreadable number in a valid file
    lines[data[2]] = ",".join(cells)
    bad_csv = tmp_path / "bad_measurements.csv"
    bad_csv.write_text("\n".join(lines) + "\n", encoding="utf-8")
    name0 = app.session.name
    open_tab(page, "File")
    page.get_by_role("button", name="Rescan folders").click()
    label = f"{tmp_path.name}/"
    wait_for(lambda: label + bad_csv.name in app.controls.file.path.options, 10, message="the rescan", page=page)
    for bad, says in ((bad_scene, "TOML syntax error"), (bad_csv, "'12.x' is not a number")):
        page.get_by_label("Scene or data file").click()
        page.get_by_role("option", name=label + bad.name, exact=True).click()
        wait_for(lambda bad=bad: app.controls.file.path.value == label + bad.name, 10, message="the pick", page=page)
        page.get_by_role("button", name="Load file").click()
        # H1 was dragged and not saved: the app asks before discarding that (again after a file that failed to
        # load: nothing was discarded); the user agrees
        page.get_by_role("button", name="Discard the edits and open").click(timeout=15_000)
        # a red notification and the status line at the top of the panel say what is wrong
        note = page.locator(".mantine-Notification-root", has_text=bad.name).filter(has_text="File not loaded")
        note.first.wait_for(state="visible", timeout=15_000)
        assert says in note.first.inner_text(), notification_texts(page)
        status = page.get_by_text(f"⚠ {bad}", exact=False).first
        status.wait_for(state="visible", timeout=15_000)
        assert says in status.inner_text()
        assert app.session.name == name0  # the current scene stays

    # 4) still connected and serving: a real drag brings H1 back inside the hull and the page says so
    assert len(app.server.get_clients()) == 1 and "Connecting" not in page.inner_text("body")
    open_tab(page, "Explore")
    moved = drag_until_moved(app, page, "H1", 0.7, 3.0)
    assert moved[0] > 0.5 * 2.3 * scale, moved
    assert 300.0 < server_position(app, "targets", "H1")[0] < 650.0
    row3 = target_row(page, "H1")
    assert row3[-1] == "inside" and row3[1:4] != row2[1:4], (row2, row3)
    wait_for(
        lambda: "outside the fiducials' hull" not in page.inner_text("body"),
        10,
        message="the extrapolation warning to go",
        page=page,
    )
    assert not [u for u in requests if not is_local_url(u, app.port)]


def test_five_tabs_share_one_state(viser_app, page_for):
    app = viser_app(lambda: serve(simple_arm=True, plain_light=True))
    # Five tabs connect concurrently. The first draws; the other four are connected clients that receive every
    # scene and GUI message but draw nothing (helpers.UNDRAWN_TAB_SCRIPT): five software-WebGL renders of the
    # cell would take most of a minute.
    opened = [page_for(app.url, wait=False, init_script=None if i == 0 else UNDRAWN_TAB_SCRIPT) for i in range(5)]
    pages = [p for p, _ in opened]
    wait_for(lambda: len(app.server.get_clients()) == 5, 45, message="5 clients in server.get_clients()", page=pages[0])
    for p in pages:  # every tab shows the panel with the server's numbers
        wait_for(
            lambda p=p: target_row(p, "H1") == expected_row(app, "H1"), 45, message="the H1 row in every tab", page=p
        )
    assert all(any(u.startswith(f"ws://127.0.0.1:{app.port}") for u in r) for _, r in opened)
    assert all(not [u for u in r if not is_local_url(u, app.port)] for _, r in opened)
    first, last = pages[0], pages[-1]
    assert node_exists(last, H1_GIZMO)  # the undrawn tabs hold the scene too

    # a setting changed in tab 1 through its own panel shows in tab 5 (and in the server's session)
    assert "Interpolation gp" not in last.inner_text("body")
    first.get_by_label("Interpolation").click()
    first.get_by_role("option", name="gp", exact=True).click()
    wait_for(
        lambda: app.session.settings.interpolation == "gp", 20, message="interpolation gp on the server", page=first
    )
    wait_for(lambda: "Interpolation gp" in last.inner_text("body"), 15, message="tab 5 to show gp", page=last)
    # gp adds a std column; tab 5 shows the server's new numbers for H1
    wait_for(
        lambda: len(target_row(last, "H1") or []) == 6 and target_row(last, "H1")[:4] == expected_row(app, "H1")[:4],
        15,
        message="tab 5's H1 row with a std column",
        page=last,
    )
    # a move made elsewhere (here from Python, as any tab's drag ends up) shows in tab 3's table
    app.evaluate.handle_drag("targets", "H2", [420.0, -50.0, 15.0], "end")
    wait_for(
        lambda: (target_row(pages[2], "H2") or [])[:4] == expected_row(app, "H2")[:4],
        15,
        message="tab 3 to show H2's new numbers",
        page=pages[2],
    )
    assert len(app.server.get_clients()) == 5
