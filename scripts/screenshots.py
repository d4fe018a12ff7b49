#!/usr/bin/env python3
"""Screenshots of the browser app in headless Chromium, for the docs.

    .venv/bin/python scripts/screenshots.py [--out docs/screenshots] [--mesh-node /mesh/cell] [--only app_default.png]

Starts the real app (``rrbc_viz.serve.serve(port=0)``, local only) once per screenshot, so every shot begins from
the same state, opens it at 1280x800 in Debian's /usr/bin/chromium (install it with
``bash scripts/setup.sh --browser``; never ``playwright install``), closes viser's "Software WebGL rendering
detected" notification, runs the shot's GUI actions, waits until the scene has rendered and the page has
settled, and saves a PNG.

Extend SHOTS below. Each entry is (file name, actions); an action is one of
    ("click", "Label")      click the visible GUI element whose text is "Label" (page.get_by_text; exact match
                            first, then substring) - checkbox labels, folder titles, dropdowns then their options
    ("tab", "Learn")        click the panel tab named "Learn" (get_by_role("tab"))
    ("button", "Next")      click the button named "Next" (get_by_role("button"), exact; "Next" also appears in text)
    ("select", ("Label", "option"))   open the dropdown labelled "Label" and choose "option"
    ("drag", (node, a, b))  real mouse drag of gizmo `node`'s X arrow from local x = a to x = b, in gizmo scales
                            (the app's ``nodes.gizmo_scale()``); waits until the server has the drag's end
    ("zoom", {"look_at": (x, y, z), "factor": f})   every tab's camera looks at (x, y, z) mm from f times its
                            initial distance, along the initial viewing direction (like a user zooming in)
    ("call", fn)            call fn(app) on the server (e.g. a drag from Python: app.evaluate.handle_drag(...))
    ("wait_text", "Text")   wait until "Text" is visible on the page
    ("wait_node", "/name")  wait until scene node "/name" is mounted in the browser
    ("sleep", 0.5)          pause (seconds); prefer the waits above
A shot whose click label does not exist in the app (yet) is skipped with a message, not an error.

PNGs larger than --max-kb are quantised to 256 colours (Pillow; the UI and scene have few colours).

Exit status: 0 if app_default.png (the first shot) was written, 1 on failure, 2 if the app or the browser is
not available.
"""

from __future__ import annotations

import argparse
import importlib
import re
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from rrbc_viz.controls import LESSON_NEXT  # noqa: E402
from rrbc_viz.mesh_nodes import GHOST_NODE  # noqa: E402
from rrbc_viz.teaching import STEPS  # noqa: E402

# (file name, actions). The labels follow rrbc_viz/controls.py as of writing (tabs "Explore", "View", "Learn";
# the heat-map layer checkbox "Heat map of predicted error" in "View", folder "Layers"; lesson button "Next");
# scene nodes follow rrbc_viz/nodes.py (/targets/<id>/gizmo). A label missing from the page skips the shot, so
# renaming a control only loses a picture until this list is updated. Coordinates: the bundled default scene
# (robot frame, mm; targets H1..H8 on the fixture plate around (475, 0, 15)).
SHOTS: list[tuple[str, list[tuple[str, Any]]]] = [
    ("app_default.png", []),
    # The nine Learn steps, each as the app frames it (the camera moves itself; no zoom here).
    *[
        (f"learn_step{k}.png", [("tab", "Learn")] + [("button", LESSON_NEXT)] * k + [("wait_text", f"Step {k} of 9")])
        for k in range(1, 10)
    ],
    # Heat map on, coloured by the rigid-only error; "Layers" folded so the legend (mm) shows; the close-up preset.
    (
        "app_heatmap.png",
        [
            ("tab", "View"),
            ("click", "Heat map of predicted error"),
            ("select", ("Colour by", "rigid error")),
            ("click", "Layers"),
            ("button", "close-up"),
        ],
    ),
    # H1 dragged 3.2 gizmo scales along -X, out of the fiducials' hull (magenta, "extrapolated" in the table), then
    # the selected-point preset: its correction arrow and its landing bullseye above it (rigid vermillion, RRBC
    # teal), and the bullseye in the panel.
    (
        "app_drag.png",
        [
            ("tab", "View"),
            ("button", "close-up"),
            ("tab", "Explore"),
            ("drag", ("/targets/H1/gizmo", 0.7, -2.5)),
            ("tab", "View"),
            ("button", "selected point"),
            ("tab", "Explore"),
        ],
    ),
    # The error slice: a horizontal plane through the plate top coloured by the RRBC error, the fiducials' hull
    # traced in white; error grows outside it. The work-area view.
    (
        "app_slice.png",
        [
            ("tab", "View"),
            ("click", "Error slice (predicted error on a plane)"),
            ("click", "Layers"),
            ("wait_text", "The plane is sampled"),
        ],
    ),
    # The landing bullseye of target H5 (selected from the list): in the panel at true size and floating above H5
    # in the scene, the view framed on it.
    (
        "app_bullseye.png",
        [("select", ("Select", "target H5")), ("tab", "View"), ("button", "selected point"), ("tab", "Explore")],
    ),
    # Each shipped scene and a measurement file as they open (the work-area view), and presentation mode on a
    # 1280x720 projector (SHOT_OPTIONS).
    ("scene_breadboard.png", []),
    ("scene_peg_in_hole.png", []),
    ("measurements.png", []),
    ("presentation_1280x720.png", [("tab", "Learn"), ("button", LESSON_NEXT), ("wait_text", "Step 1 of 9")]),
    # and its steps 5 (a fiducial's two readings) and 6 (the fiducials' corrections, the largest named)
    *(
        (
            f"presentation_step{k}_1280x720.png",
            [("tab", "Learn")] + [("button", LESSON_NEXT)] * k + [("wait_text", f"Step {k} of 9")],
        )
        for k in (5, 6)
    ),
    # The results table with gp (a std column beside the others), the method chosen in the panel.
    ("app_gp_table.png", [("select", ("Interpolation", "gp")), ("wait_text", "std")]),
    # Arm (VEC) tab: VEC compared with rigid and RRBC, the registration points measured in varied orientations and
    # H1 reached with its tool leaned 40° (the arm drawn so): RRBC's error at H1 grows, VEC's does not; the
    # selected-point view shows H1's bullseye with VEC's landing (brown).
    (
        "app_vec.png",
        [
            ("tab", "Arm (VEC)"),
            ("click", "Compare with VEC"),
            ("wait_text", "VEC identified"),
            ("call", lambda app: app.vec.set_varied_registration(True)),
            ("call", lambda app: app.vec.set_target_tool("H1", 40.0, 0.0)),
            ("wait_text", "40°, 0°"),
            ("tab", "View"),
            ("button", "selected point"),
            ("tab", "Arm (VEC)"),
        ],
    ),
    # Plan tab: F1 slid in under the plate (as a fiducial drag does), so H1's region leaves the hull (red halo;
    # the others blue, covered); regions coloured by coverage; Suggest's four ghost spheres (+1 … +4) with the
    # predicted gain in the panel. Correction arrows and landing points hidden (less clutter).
    (
        "planning.png",
        [
            ("tab", "View"),
            ("click", "Correction arrows"),
            ("click", "Landing points (rigid vs RRBC)"),
            ("button", "close-up"),
            ("tab", "Plan"),
            ("click", "Colour regions by coverage"),
            ("call", lambda app: app.evaluate.handle_drag("fiducials", "F1", [400.0, -60.0, 0.0], "end")),
            ("button", "Suggest"),
            ("wait_text", "Suggested: 4 fiducials"),
        ],
    ),
]


def _bench_stl() -> bytes:
    """An integrator's own cell mesh as an STL (robot frame, mm): a bench top at z = 0 in front of the robot with a
    fixture block on it."""
    import trimesh

    bench = trimesh.creation.box(extents=(800.0, 700.0, 40.0))
    bench.apply_translation((480.0, 0.0, -20.0))
    block = trimesh.creation.box(extents=(160.0, 120.0, 60.0))
    block.apply_translation((520.0, 120.0, 30.0))
    return trimesh.util.concatenate([bench, block]).export(file_type="stl")


# The integrator's start: their own mesh uploaded (bench_v3.stl), then File -> New cell from this mesh: the demo's
# points gone, one target and the registration points over it, the camera on the whole cell.
SHOTS.append(
    (
        "new_cell_from_mesh.png",
        [
            ("call", lambda app: app.authoring.upload_mesh("bench_v3.stl", _bench_stl())),
            ("tab", "File"),
            ("button", "New cell from this mesh"),
            ("wait_text", "A new cell on bench_v3.stl"),
        ],
    )
)
# The File tab on an integrator's laptop (1440x900).
SHOTS.append(("file_tab_1440x900.png", [("tab", "File")]))
# The opening view on a wide screen (1600x900): the work framed, the arm as context (issue 39).
SHOTS.append(("app_default_1600x900.png", []))
# A measured file of an arm whose URDF has no geometry (drawn as links between its joints), and a real station of
# the public stationing data (only with --stationing-data: those data are not ours to ship).
SHOTS.append(("urdf_without_meshes.png", [("wait_node", "/arm/joint0")]))
SHOTS.append(("real_station.png", [("wait_node", "/arm/joint0")]))


def _lift_arm_file(tmp: Path, stationing_data: Path | None) -> dict | None:
    """A simulated measurement file of the packaged lift arm (a URDF without visual or collision geometry)."""
    from rrbc_core.io.measurements_write import write_measurements
    from rrbc_core.models.urdf import load_urdf
    from rrbc_core.simulation.arm_data import chain_measurements

    path = tmp / "lift_arm.csv"
    write_measurements(path, chain_measurements(load_urdf("lift_arm"), 2, n_fid=12, n_chk=6, n_tgt=2, noise_mm=0.05))
    return {"source": str(path), "urdf": "lift_arm"}


def _real_station(tmp: Path, stationing_data: Path | None) -> dict | None:
    """The public stationing data's `flat` set converted as `rrbc convert --to csv --urdf trailblazer.urdf` does
    (docs/real_data.md); None (the shot is skipped) without a copy of those data."""
    if stationing_data is None:
        return None
    from rrbc_core.io.measurements_write import write_measurements
    from rrbc_core.io.stationing_yaml import read_stationing_yaml
    from rrbc_core.models.urdf import load_urdf
    from rrbc_core.studies.stationing_study import paths

    urdf, files = paths(stationing_data)
    path = tmp / "flat.csv"
    write_measurements(path, read_stationing_yaml(files["flat"], load_urdf(str(urdf), tip="prism")))
    return {"source": str(path), "urdf": str(urdf), "tip": "prism"}


#: Per-shot options: "serve" (keyword arguments of serve: a source, presentation mode) and "viewport" (the
#: browser window, default helpers.VIEWPORT 1280x800).
SCENES = ROOT / "scenes"
SHOT_OPTIONS: dict[str, dict] = {
    "scene_breadboard.png": {"serve": {"source": str(SCENES / "breadboard_vanwyk2018.toml")}},
    "scene_peg_in_hole.png": {"serve": {"source": str(SCENES / "peg_in_hole_cell.toml")}},
    "measurements.png": {
        "serve": {"source": str(ROOT / "rrbc_core" / "data" / "example_measurements.csv")},
        "mesh_node": "/registration/points",  # no work-cell mesh with this file: wait for the points instead
    },
    "presentation_1280x720.png": {
        "serve": {"present": True},
        "viewport": {"width": 1280, "height": 720},
        **({"mesh_node_after": GHOST_NODE} if STEPS[0].see_through else {}),
    },
    **{
        f"presentation_step{k}_1280x720.png": {
            "serve": {"present": True},
            "viewport": {"width": 1280, "height": 720},
            **({"mesh_node_after": GHOST_NODE} if STEPS[k - 1].see_through else {}),
        }
        for k in (5, 6)
    },
    "file_tab_1440x900.png": {"viewport": {"width": 1440, "height": 900}},
    "app_default_1600x900.png": {"viewport": {"width": 1600, "height": 900}},
    "urdf_without_meshes.png": {"make": _lift_arm_file, "mesh_node": "/registration/points"},
    "real_station.png": {"make": _real_station, "mesh_node": "/registration/points"},
}
# a lesson step that draws the cell see-through has, after its actions, only the see-through mesh node
# (rrbc_viz/mesh_nodes.py: only the node shown exists)
SHOT_OPTIONS.update(
    {f"learn_step{k + 1}.png": {"mesh_node_after": GHOST_NODE} for k, step in enumerate(STEPS) if step.see_through}
)

APP_ENTRY = "rrbc_viz.serve:serve"
DEFAULT_MESH_NODE = "/mesh/cell"  # rrbc_viz/nodes.py
MAX_KB = 400
CLICK_TIMEOUT_S = 5.0
RENDER_TIMEOUT_S = 60.0
SETTLE_TIMEOUT_S = 15.0


class ShotSkipped(Exception):
    pass


def unavailable(message: str) -> None:
    """Exit 2: the app or the browser is not there (as opposed to a failed screenshot, exit 1)."""
    print(f"screenshots: {message}", file=sys.stderr)
    sys.exit(2)


def load_serve(entry: str) -> tuple[Any, Callable[..., Any]]:
    """Import ``module:function``; exit 2 with a clear message if the module itself does not exist yet."""
    module_name, _, func_name = entry.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name in {"viser", "numpy", "playwright", "trimesh", "scipy"}:
            unavailable(f"{exc}: run this with the project's .venv/bin/python (after `bash scripts/setup.sh`).")
        if exc.name is not None and (module_name == exc.name or module_name.startswith(exc.name + ".")):
            unavailable(
                f"the app module {module_name!r} does not exist yet ({exc}); nothing to screenshot. "
                f"It should provide {func_name or 'serve'}(source=None, host='127.0.0.1', port=0) -> RunningApp."
            )
        raise  # the app exists but one of its own imports failed: show the real traceback
    serve = getattr(module, func_name or "serve", None)
    if serve is None:
        unavailable(f"{module_name} has no function {func_name or 'serve'!r} yet.")
    return module, serve


def click_label(page: Any, label: str) -> None:
    for exact in (True, False):
        loc = page.get_by_text(label, exact=exact).filter(visible=True).first
        try:
            loc.wait_for(state="visible", timeout=CLICK_TIMEOUT_S * 1000 if exact else 1000)
        except Exception:  # noqa: BLE001 - try the looser match, then give up
            continue
        loc.click()
        return
    debug = Path(tempfile.gettempdir()) / f"screenshots-missing-{label.replace('/', '_')[:40]}.png"
    page.screenshot(path=str(debug))
    raise ShotSkipped(f"no visible GUI element labelled {label!r} (page as it was: {debug})")


def click_role(page: Any, role: str, name: str | re.Pattern) -> None:
    loc = page.get_by_role(role, name=name, exact=isinstance(name, str)).filter(visible=True).first
    try:
        loc.wait_for(state="visible", timeout=CLICK_TIMEOUT_S * 1000)
    except Exception:  # noqa: BLE001
        raise ShotSkipped(f"no visible {role} named {name!r}") from None
    loc.click()
    page.wait_for_timeout(150)  # let the server's reaction (e.g. the next lesson step) arrive


def drag_gizmo(page: Any, h: Any, app: Any, node: str, a: float, b: float) -> None:
    """Drag gizmo `node`'s X arrow with the real mouse and wait until the server's handle has moved (one retry
    if the press missed the arrow)."""
    scale = float(app.nodes.gizmo_scale())
    h.wait_for_node(page, node, RENDER_TIMEOUT_S)
    handle = app.server.scene.get_handle_by_name(node)
    if handle is None:
        raise ShotSkipped(f"no scene node {node!r} on the server")
    p0 = np.array(handle.position, float)
    messages = len(app.messages)
    for _attempt in range(2):
        start = h.node_screen_position(page, node, (a * scale, 0.0, 0.0))
        end = h.node_screen_position(page, node, (b * scale, 0.0, 0.0))
        h.drag(page, start, end, steps=20)
        try:
            h.wait_for(lambda: not np.allclose(handle.position, p0), 10, message=f"{node} to move", page=page)
            break
        except TimeoutError:
            continue
    else:
        raise RuntimeError(f"dragging {node} did not move it")
    page.wait_for_timeout(500)  # the drag's end: table, heat map, Monte Carlo request
    if len(app.messages) > messages:
        print(f"screenshots: the app said: {app.messages[-1]}", file=sys.stderr)


def zoom(app: Any, look_at, factor: float) -> None:
    """Every tab's camera: look at `look_at` from `factor` times the initial camera distance, same direction."""
    cam = app.server.initial_camera
    pos0, look0 = np.asarray(cam.position, float), np.asarray(cam.look_at, float)
    look = np.asarray(look_at, float)
    position = look + (pos0 - look0) * float(factor)
    for client in app.server.get_clients().values():
        with client.atomic():
            client.camera.look_at = look
            client.camera.position = position


def run_action(page: Any, h: Any, app: Any, action: tuple[str, Any]) -> None:
    kind, arg = action
    if kind == "click":
        click_label(page, str(arg))
    elif kind == "tab":
        click_role(page, "tab", str(arg))
    elif kind == "button":
        click_role(page, "button", str(arg))
    elif kind == "select":
        label, option = arg
        box = page.get_by_label(str(label), exact=True).filter(visible=True).first
        try:
            box.wait_for(state="visible", timeout=CLICK_TIMEOUT_S * 1000)
        except Exception:  # noqa: BLE001
            raise ShotSkipped(f"no visible dropdown labelled {label!r}") from None
        box.click()
        # an option is named by its text, or starts with it (the point list adds each point's numbers: "target H5 · …")
        click_role(page, "option", re.compile(rf"^{re.escape(str(option))}( · .*)?$"))
    elif kind == "drag":
        drag_gizmo(page, h, app, *arg)
    elif kind == "zoom":
        zoom(app, arg["look_at"], arg["factor"])
        page.wait_for_timeout(500)
    elif kind == "call":
        arg(app)
        page.wait_for_timeout(300)
    elif kind == "wait_text":
        page.get_by_text(str(arg)).first.wait_for(state="visible", timeout=RENDER_TIMEOUT_S * 1000)
    elif kind == "wait_node":
        h.wait_for_node(page, str(arg), RENDER_TIMEOUT_S)
    elif kind == "sleep":
        page.wait_for_timeout(float(arg) * 1000)
    else:
        raise ValueError(
            f"unknown action {kind!r} (use click, tab, button, select, drag, zoom, call, wait_text, wait_node, sleep)"
        )


def wait_for_scene(page: Any, h: Any, mesh_node: str | None) -> str:
    """Wait until the mesh node is mounted with geometry and its screen region is not blank. Returns its name."""

    def ready() -> str | None:
        name = mesh_node
        if name is None:
            names = h.mesh_node_names(page)
            name = names[0] if names else None
        elif not h.node_exists(page, name):
            return None
        if name is None:
            return None
        box = h.node_screen_box(page, name)
        png = page.screenshot(clip=box) if box else h.canvas_png(page, inset=0.2)
        return name if h.canvas_not_blank(png) else None

    what = f"mesh node {mesh_node!r}" if mesh_node else "a mesh node (GLB or simple mesh)"
    return h.wait_for(ready, RENDER_TIMEOUT_S, interval_s=0.2, message=f"{what} rendered, not blank")


def wait_settled(page: Any, timeout_s: float = SETTLE_TIMEOUT_S, quiet_s: float = 1.0) -> bool:
    """Full-page screenshots stay identical for ``quiet_s`` (GUI and scene updates, e.g. a heat map the server
    takes a moment to compute, have arrived). False if the page is still changing after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    prev, since = page.screenshot(), time.monotonic()
    while time.monotonic() < deadline:
        page.wait_for_timeout(200)
        cur = page.screenshot()
        if cur != prev:
            prev, since = cur, time.monotonic()
        elif time.monotonic() - since >= quiet_s:
            return True
    return False


def shrink_png(path: Path, max_kb: float) -> None:
    """Quantise the PNG to 256 colours (then 128) if it is larger than `max_kb`."""
    if path.stat().st_size <= max_kb * 1024:
        return
    from PIL import Image

    with Image.open(path) as im:
        rgb = im.convert("RGB")
    for colours in (256, 128):
        rgb.quantize(colors=colours, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(
            path, optimize=True
        )
        if path.stat().st_size <= max_kb * 1024:
            return
    print(f"screenshots: {path.name} is still {path.stat().st_size / 1024:.0f} KB", file=sys.stderr)


def take_shot(
    browser: Any,
    h: Any,
    serve: Callable[..., Any],
    mesh_node: str | None,
    name: str,
    actions: list[tuple[str, Any]],
    out: Path,
    max_kb: float = MAX_KB,
    stationing_data: Path | None = None,
) -> Path:
    opts = dict(SHOT_OPTIONS.get(name, {}))
    mesh_node = opts.get("mesh_node", mesh_node)
    kwargs = dict(opts.get("serve", {}))
    if "make" in opts:  # a file made for the shot (kept until the shot is taken)
        made = opts["make"](Path(tempfile.mkdtemp(prefix="rrbc-shot-")), stationing_data)
        if made is None:
            raise ShotSkipped("needs --stationing-data")
        kwargs.update(made)
    app = serve(port=0, **kwargs)
    try:
        h.wait_for_port(int(app.port), timeout_s=30)
        ctx = browser.new_context(viewport=dict(opts.get("viewport", h.VIEWPORT)))
        try:
            page = ctx.new_page()
            page.set_default_timeout(RENDER_TIMEOUT_S * 1000)
            page.goto(h.app_url(app), wait_until="domcontentloaded")
            h.wait_client_ready(page, RENDER_TIMEOUT_S)
            found = wait_for_scene(page, h, mesh_node)
            h.dismiss_software_webgl_notification(page, timeout_s=2.0)
            for action in actions:
                run_action(page, h, app, action)
            if actions:
                page.wait_for_timeout(300)  # let the server's reaction arrive before checking for stillness
                wait_for_scene(page, h, opts.get("mesh_node_after", mesh_node or found))
            if not wait_settled(page):
                print(
                    f"screenshots: {name}: page still changing after {SETTLE_TIMEOUT_S:.0f} s; saving anyway",
                    file=sys.stderr,
                )
            h.dismiss_software_webgl_notification(page, timeout_s=0.2)  # in case it reappeared
            path = out / name
            page.screenshot(path=str(path))
            shrink_png(path, max_kb)
            return path
        finally:
            ctx.close()
    finally:
        app.stop()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "screenshots", help="output directory")
    ap.add_argument(
        "--mesh-node",
        default=None,
        help=f"scene node to wait for (default: the app module's MESH_NODE if it defines one, "
        f"else {DEFAULT_MESH_NODE}; 'any' for any mesh node)",
    )
    ap.add_argument("--max-kb", type=float, default=MAX_KB, help=f"quantise PNGs above this size (default {MAX_KB})")
    ap.add_argument("--only", action="append", default=None, help="only this file name (repeatable)")
    ap.add_argument(
        "--stationing-data",
        type=Path,
        default=None,
        help="a copy of github.com/Hilti-Research/construction_robot_stationing_datasets (real_station.png)",
    )
    ap.add_argument("--app", default=APP_ENTRY, help=f"module:function that starts the app (default {APP_ENTRY})")
    args = ap.parse_args(argv)

    module, serve = load_serve(args.app)
    mesh_node = args.mesh_node or getattr(module, "MESH_NODE", None) or DEFAULT_MESH_NODE
    if mesh_node == "any":
        mesh_node = None

    from tests.browser import helpers as h

    if not Path(h.CHROMIUM_PATH).exists():
        unavailable(f"{h.CHROMIUM_PATH} is missing; run `bash scripts/setup.sh --browser` (not `playwright install`).")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        unavailable("playwright is not installed; run with .venv/bin/python after scripts/setup.sh")

    shots = [s for s in SHOTS if not args.only or s[0] in args.only]
    args.out.mkdir(parents=True, exist_ok=True)
    written, failed = [], []
    with sync_playwright() as pw:
        browser = h.launch_chromium(pw)
        try:
            for name, actions in shots:
                t0 = time.monotonic()
                try:
                    path = take_shot(
                        browser, h, serve, mesh_node, name, actions, args.out, args.max_kb, args.stationing_data
                    )
                except ShotSkipped as exc:
                    print(f"screenshots: {name}: skipped ({exc})", file=sys.stderr)
                    continue
                except Exception as exc:  # noqa: BLE001 - report and go on with the other shots
                    print(f"screenshots: {name}: FAILED: {type(exc).__name__}: {exc}", file=sys.stderr)
                    failed.append(name)
                    continue
                written.append(name)
                print(f"screenshots: wrote {path} ({path.stat().st_size / 1024:.0f} KB, {time.monotonic() - t0:.1f} s)")
        finally:
            browser.close()
    if failed or (shots and shots[0][0] == SHOTS[0][0] and SHOTS[0][0] not in written):
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
