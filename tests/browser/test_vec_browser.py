"""The Arm (VEC) tab in headless Chromium, as a user sees it (issue 15, item 4): open the tab, tick *Compare with
VEC* and read rigid, RRBC and VEC errors per target from the page (equal to the server's session); see VEC's
landing appear on screen in the bullseye; measure the registration points in varied orientations, lean the first
target's tool with the slider's keys, and read that RRBC's error at it grew while VEC's stayed below it."""

from __future__ import annotations

import re
import tempfile
from pathlib import Path

import pytest

from rrbc_core.session import vec_view
from rrbc_viz.serve import serve

from .helpers import canvas_rect, node_exists, node_screen_position, wait_for, wait_until_rendered

pytestmark = pytest.mark.browser
_SHOTS = Path(tempfile.gettempdir())


def page_row(page, pid: str) -> tuple[str, float, float, float] | None:
    """(tool, rigid, RRBC, VEC) of target pid as the tab's table shows it, or None."""
    m = re.search(
        rf"\b{re.escape(pid)}\s+(down|\d+°, -?\d+°)\s+([0-9.]+)\s+([0-9.]+)\s+([0-9.]+)", page.inner_text("body")
    )
    return (m.group(1), float(m.group(2)), float(m.group(3)), float(m.group(4))) if m else None


def test_vec_tab_compares_and_a_leaned_tool_shows_what_rrbc_cannot_follow(viser_app, page_for):
    app = viser_app(lambda: serve(plain_light=True))
    page, _ = page_for(app.url)
    wait_until_rendered(page, "/targets/H1/gizmo", timeout_s=60)
    page.get_by_role("tab", name="Arm (VEC)", exact=True).click()
    page.get_by_label("Compare with VEC").click()
    pid = app.session.layout["targets"].ids[0]
    wait_for(lambda: page_row(page, pid) is not None, 30, message="the VEC table", page=page)
    view = vec_view.vec_view(app.session)
    assert page_row(page, pid) == (
        "down",
        round(float(view.error_rigid[0]), 3),
        round(float(view.error_rrbc[0]), 3),
        round(float(view.error_vec[0]), 3),
    )
    # VEC's landing in the bullseye, inside the 3-D view
    wait_for(lambda: node_exists(page, "/landing/vec"), 20, message="VEC's landing node", page=page)
    rect = canvas_rect(page)
    x, y = node_screen_position(page, "/landing/vec")
    assert rect["x"] < x < rect["x"] + rect["width"] and rect["y"] < y < rect["y"] + rect["height"], (x, y)

    page.get_by_label("Registration points in varied orientations").click()
    wait_for(lambda: app.session.varied_registration, 20, message="varied registration on the server", page=page)
    before = page_row(page, pid)
    tilt = page.locator("[role=slider]").nth(_slider_index(page, "Tool tilt"))
    tilt.focus()
    for _ in range(40):
        tilt.press("ArrowRight")
    wait_for(lambda: (page_row(page, pid) or ("down",))[0].startswith("40°"), 90, message="the leaned tool", page=page)
    tool, rigid, rrbc, vec = page_row(page, pid)
    assert app.session.tool_of("targets", pid) == (40.0, 0.0)
    assert rrbc > before[2] and vec < rrbc, (before, (tool, rigid, rrbc, vec))
    page.screenshot(path=str(_SHOTS / "vec_tab_leaned_tool.png"))


def _slider_index(page, label: str) -> int:
    """Which of the page's sliders (document order) is labelled `label`: among the visible ones, the one whose
    nearest ancestor holding the label's text is closest."""
    return page.evaluate(
        """(label) => {
            const sliders = [...document.querySelectorAll('[role=slider]')];
            let best = -1, bestDepth = 99;
            sliders.forEach((s, k) => {
                if (s.offsetParent === null) return;
                let el = s;
                for (let depth = 0; depth < 8 && el; depth++, el = el.parentElement) {
                    if (el.innerText && el.innerText.includes(label)) {
                        if (depth < bestDepth) { best = k; bestDepth = depth; }
                        return;
                    }
                }
            });
            return best;
        }""",
        label,
    )
