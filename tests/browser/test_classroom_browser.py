"""The classroom, in headless Chromium: one session per tab (`rrbc view --per-client`) isolates two tabs (shared
mode syncing them is tests/browser/test_app_browser.py::test_five_tabs_share_one_state), and presentation mode is
legible at 1280x720 (a projector): panel text of at least 24 px, every control reachable by scrolling, the lesson's
Next in view without scrolling, and the fixture plate a few hundred pixels wide beside the panel.
"""

from __future__ import annotations

import numpy as np
import pytest

from rrbc_viz.camera import PRESENTATION_PANEL_WIDTH_PX
from rrbc_viz.serve import serve

from .helpers import (
    UNDRAWN_TAB_SCRIPT,
    dismiss_software_webgl_notification,
    new_context,
    next_frames,
    wait_camera,
    wait_for,
)

#: a watcher in tab 2's page: window.__sawGp turns true the moment its text shows "Interpolation gp"
_JS_WATCH_GP = """() => { window.__sawGp = false;
  const look = () => { if ((document.body.innerText || '').includes('Interpolation gp')) window.__sawGp = true; };
  new MutationObserver(look).observe(document.body, {subtree: true, childList: true, characterData: true});
  look(); return true; }"""

pytestmark = pytest.mark.browser

# Font sizes (px) of the panel's visible text: paragraphs, table cells, labels, buttons -> how many elements.
_JS_FONT_SIZES = """() => { const out = {};
  for (const el of document.querySelectorAll('p, td, label, button')) {
    if (!(el.innerText || '').trim() || !el.offsetParent) continue;
    const fs = parseFloat(getComputedStyle(el).fontSize); out[fs] = (out[fs] || 0) + 1; }
  return out; }"""

# The panel's scroll area: its bottom edge, and after scrolling it to the end, the last control's bottom edge.
_JS_PANEL_SCROLL = """() => { const v = document.querySelector('.mantine-Paper-root .mantine-ScrollArea-viewport');
  v.scrollTop = v.scrollHeight; const r = v.getBoundingClientRect();
  const all = [...v.querySelectorAll('button, input, label, p')].filter((e) => e.offsetParent);
  const last = all[all.length - 1].getBoundingClientRect();
  return {bottom: r.bottom, lastBottom: last.bottom, scrolled: v.scrollTop}; }"""
_JS_SCROLL_TOP = (
    """() => { document.querySelector('.mantine-Paper-root .mantine-ScrollArea-viewport').scrollTop = 0; }"""
)
_JS_SCROLLED = """() => document.querySelector('.mantine-Paper-root .mantine-ScrollArea-viewport').scrollTop"""

_JS_PROJECT = """(pts) => { const m = window.__viserMutable; const obj = m.nodeRefFromName['/mesh'];
  obj.updateWorldMatrix(true, false); m.camera.updateMatrixWorld(); const V = m.camera.position.constructor;
  const r = m.canvas.getBoundingClientRect();
  return pts.map((p) => { const q = obj.localToWorld(new V(p[0], p[1], p[2])).project(m.camera);
    return [r.left + (q.x + 1) / 2 * r.width, r.top + (1 - q.y) / 2 * r.height]; }); }"""


def test_per_client_mode_gives_each_tab_its_own_session(viser_app, page_for):
    app = viser_app(lambda: serve(per_client=True, simple_arm=True, plain_light=True))
    first, _ = page_for(app.url)
    second, _ = page_for(app.url, init_script=UNDRAWN_TAB_SCRIPT)
    wait_for(lambda: len(app.apps) == 2, 30, message="two tabs, two apps", page=first)
    apps = list(app.apps.values())
    assert apps[0].session is not apps[1].session
    for p in (first, second):
        p.get_by_text("Interpolation idw", exact=False).first.wait_for(state="visible", timeout=30_000)
    second.evaluate(_JS_WATCH_GP)  # from now on, note whether tab 2 ever shows gp
    # a setting changed in tab 1 through its own panel changes tab 1's session only
    first.get_by_label("Interpolation").click()
    first.get_by_role("option", name="gp", exact=True).click()
    wait_for(lambda: "Interpolation gp" in first.inner_text("body"), 20, message="tab 1 to show gp", page=first)
    gp = [a for a in app.apps.values() if a.session.settings.interpolation == "gp"]
    assert len(gp) == 1
    # tab 2 never showed it: a setting changed in tab 2 afterwards reaches its page after anything sent to it before
    # (one websocket, in order), and a watcher in the page notes whether gp was ever shown
    second.get_by_label("Interpolation").click()
    second.get_by_role("option", name="linear", exact=True).click()
    wait_for(lambda: "Interpolation linear" in second.inner_text("body"), 20, message="tab 2's own change", page=second)
    assert second.evaluate("() => window.__sawGp") is False
    assert "Interpolation gp" in first.inner_text("body")
    # closing a tab stops its app (the other keeps running)
    second.close()
    wait_for(lambda: len(app.apps) == 1, 15, message="the closed tab's app stopped", page=first)


def test_presentation_mode_is_legible_on_a_1280x720_projector(viser_app, browser):
    app = viser_app(lambda: serve(present=True, simple_arm=True, plain_light=True))
    context = new_context(browser, {"width": 1280, "height": 720})
    try:
        page = context.new_page()
        page.goto(app.url)
        page.wait_for_function("() => window.__viserMutable && window.__viserMutable.canvas", timeout=30_000)
        page.get_by_text("Selected point").first.wait_for(state="visible", timeout=30_000)
        dismiss_software_webgl_notification(page, timeout_s=5.0)
        wait_camera(page, app)  # the tab reports its camera; the app frames the view for it
        sizes = page.evaluate(_JS_FONT_SIZES)
        total = sum(sizes.values())
        big = sum(n for fs, n in sizes.items() if float(fs) >= 24.0 - 0.1)
        assert total > 20 and big / total > 0.9, sizes
        # the fixture plate's top (300 x 400 mm, centred at (475, 0, 15)) spans a few hundred pixels, left of the
        # (wider) panel
        corners = [[325, -200, 15], [625, -200, 15], [625, 200, 15], [325, 200, 15]]
        xy = np.array(page.evaluate(_JS_PROJECT, corners))
        width = xy[:, 0].max() - xy[:, 0].min()
        assert width > 250, xy
        assert xy[:, 0].max() < 1280 - PRESENTATION_PANEL_WIDTH_PX  # left of the panel
        # every control reachable and the lesson's Next in view: test_every_tab_of_the_panel_can_be_scrolled_...
    finally:
        context.close()


_JS_TAB_TOPS = """() => [...document.querySelectorAll('.mantine-Paper-root [role=tab]')]
  .filter(t => t.offsetParent).map(t => Math.round(t.getBoundingClientRect().top))"""
_JS_TEXT_TOP = """(words) => { for (const el of document.querySelectorAll('.mantine-Paper-root p, .mantine-Paper-root strong')) {
    if (el.offsetParent && (el.innerText || '').includes(words)) return el.getBoundingClientRect().top; }
  return null; }"""

_JS_MIN_FONT = """() => { let lo = 1e9;
  for (const el of document.querySelectorAll('p, td, label, button')) {
    if (!(el.innerText || '').trim() || !el.offsetParent) continue;
    lo = Math.min(lo, parseFloat(getComputedStyle(el).fontSize)); }
  return lo; }"""


@pytest.mark.parametrize(
    "present,width,height,min_font", [(False, 1440, 900, 11.0), (True, 1280, 720, 24.0)], ids=["1440x900", "projector"]
)
def test_every_tab_of_the_panel_can_be_scrolled_to_its_last_control(
    viser_app, browser, present, width, height, min_font
):
    """Issue 30: at 1440x900 (an integrator's laptop) and on a 1280x720 projector, every tab's last control can be
    scrolled into the window (the File tab's *New cell from this mesh* among them), no panel text is smaller than
    the mode's size, and the lesson's Next and Previous are in view without scrolling at every step."""
    app = viser_app(lambda: serve(present=present, simple_arm=True, plain_light=True))
    context = new_context(browser, {"width": width, "height": height})
    try:
        page = context.new_page()
        page.add_init_script(UNDRAWN_TAB_SCRIPT)  # the panel's layout is what is tested: the 3-D view draws nothing
        page.goto(app.url)
        page.wait_for_function("() => window.__viserMutable && window.__viserMutable.canvas", timeout=30_000)
        page.get_by_text("Selected point").first.wait_for(state="visible", timeout=30_000)
        dismiss_software_webgl_notification(page, timeout_s=5.0)
        tabs = [t for t in page.get_by_role("tab").all_inner_texts() if t.strip()]
        assert {"Explore", "Learn", "File"} <= set(tabs), tabs
        for name in tabs:
            tab = page.get_by_role("tab", name=name, exact=True)
            tab.click()
            wait_for(lambda t=tab: t.get_attribute("aria-selected") == "true", 10, message=f"tab {name}", page=page)
            next_frames(page, 2)  # its panel laid out and drawn
            box = page.evaluate(_JS_PANEL_SCROLL)
            assert box["bottom"] <= height + 1, (name, box)
            assert box["lastBottom"] <= height + 1, (name, box)
            assert page.evaluate(_JS_MIN_FONT) >= min_font - 0.1, name
            if name == "File":
                button = page.get_by_role("button", name="New cell from this mesh")
                button.scroll_into_view_if_needed()
                b = button.bounding_box()
                assert b is not None and 0 <= b["y"] and b["y"] + b["height"] <= height, b
            page.evaluate(_JS_SCROLL_TOP)
        if present:  # issue 39: the tabs on one row (the open one named, the others as icons)
            tops = page.evaluate(_JS_TAB_TOPS)
            assert len(tops) >= 8 and max(tops) - min(tops) < 2, tops
        page.get_by_role("tab", name="Learn", exact=True).click()
        for k in range(10):  # the prompt, then steps 1 to 9
            nxt = page.get_by_role("button", name="Next")
            b = nxt.bounding_box()
            assert b is not None and 0 <= b["y"] and b["y"] + b["height"] <= height, (k, b)
            if k > 0:  # issue 39: Previous beside Next, in view without scrolling too
                p = page.get_by_role("button", name="Previous").bounding_box()
                assert p is not None and abs(p["y"] - b["y"]) < 2, (k, p, b)
            assert page.evaluate(_JS_SCROLLED) < 1.0, k
            if present and k > 0:  # issue 39: a step's text starts in the window's upper half on the projector
                top = page.evaluate(_JS_TEXT_TOP, f"Step {k} of 9")
                assert top is not None and top < height / 2, (k, top)
                # ... and is read whole without scrolling: the button below it is in the window
                end = page.get_by_role("button", name="End lesson (restore layers)").bounding_box()
                assert end is not None and end["y"] + end["height"] <= height, (k, end)
            if k == 9:
                break
            nxt.click()
            wait_for(
                lambda k=k: f"Step {k + 1} of 9" in page.inner_text("body"), 20, message=f"step {k + 1}", page=page
            )
            page.evaluate(_JS_SCROLL_TOP)
    finally:
        context.close()
