"""The classroom, in headless Chromium: one session per tab (`rrbc view --per-client`) isolates two tabs (shared
mode syncing them is tests/browser/test_app_browser.py::test_five_tabs_share_one_state), and presentation mode is
legible at 1280x720 (a projector): panel text of at least 16 px and the fixture plate several hundred pixels wide.
"""

from __future__ import annotations

import numpy as np
import pytest

from rrbc_viz.serve import serve

from .helpers import UNDRAWN_TAB_SCRIPT, dismiss_software_webgl_notification, wait_for

pytestmark = pytest.mark.browser

# Font sizes (px) of the panel's visible text: paragraphs, table cells, labels, buttons -> how many elements.
_JS_FONT_SIZES = """() => { const out = {};
  for (const el of document.querySelectorAll('p, td, label, button')) {
    if (!(el.innerText || '').trim() || !el.offsetParent) continue;
    const fs = parseFloat(getComputedStyle(el).fontSize); out[fs] = (out[fs] || 0) + 1; }
  return out; }"""

_JS_PROJECT = """(pts) => { const m = window.__viserMutable; const obj = m.nodeRefFromName['/mesh'];
  obj.updateWorldMatrix(true, false); m.camera.updateMatrixWorld(); const V = m.camera.position.constructor;
  const r = m.canvas.getBoundingClientRect();
  return pts.map((p) => { const q = obj.localToWorld(new V(p[0], p[1], p[2])).project(m.camera);
    return [r.left + (q.x + 1) / 2 * r.width, r.top + (1 - q.y) / 2 * r.height]; }); }"""


def test_per_client_mode_gives_each_tab_its_own_session(viser_app, page_for):
    app = viser_app(lambda: serve(per_client=True))
    first, _ = page_for(app.url)
    second, _ = page_for(app.url, init_script=UNDRAWN_TAB_SCRIPT)
    wait_for(lambda: len(app.apps) == 2, 30, message="two tabs, two apps", page=first)
    apps = list(app.apps.values())
    assert apps[0].session is not apps[1].session
    for p in (first, second):
        p.get_by_text("Interpolation idw", exact=False).first.wait_for(state="visible", timeout=30_000)
    # a setting changed in tab 1 through its own panel changes tab 1's session only
    first.get_by_label("Interpolation").click()
    first.get_by_role("option", name="gp", exact=True).click()
    wait_for(lambda: "Interpolation gp" in first.inner_text("body"), 20, message="tab 1 to show gp", page=first)
    gp = [a for a in app.apps.values() if a.session.settings.interpolation == "gp"]
    assert len(gp) == 1
    second.wait_for_timeout(1500)
    assert "Interpolation gp" not in second.inner_text("body") and "Interpolation idw" in second.inner_text("body")
    # closing a tab stops its app (the other keeps running)
    second.close()
    wait_for(lambda: len(app.apps) == 1, 15, message="the closed tab's app stopped", page=first)


def test_presentation_mode_is_legible_on_a_1280x720_projector(viser_app, browser):
    app = viser_app(lambda: serve(present=True))
    context = browser.new_context(viewport={"width": 1280, "height": 720})
    try:
        page = context.new_page()
        page.goto(app.url)
        page.wait_for_function("() => window.__viserMutable && window.__viserMutable.canvas", timeout=30_000)
        page.get_by_text("Selected point").first.wait_for(state="visible", timeout=30_000)
        dismiss_software_webgl_notification(page, timeout_s=5.0)
        page.wait_for_timeout(1500)  # the tab reports its camera; the app frames the view for it
        sizes = page.evaluate(_JS_FONT_SIZES)
        total = sum(sizes.values())
        big = sum(n for fs, n in sizes.items() if float(fs) >= 16.0)
        assert total > 20 and big / total > 0.9, sizes
        # the fixture plate's top (300 x 400 mm, centred at (475, 0, 15)) spans several hundred pixels
        corners = [[325, -200, 15], [625, -200, 15], [625, 200, 15], [325, 200, 15]]
        xy = np.array(page.evaluate(_JS_PROJECT, corners))
        width = xy[:, 0].max() - xy[:, 0].min()
        assert width > 350, xy
        assert xy[:, 0].max() < 1280 - 384  # left of the panel
    finally:
        context.close()
