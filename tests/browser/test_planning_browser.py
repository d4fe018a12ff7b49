"""The Plan tab in headless Chromium, as a user sees it: open the tab, read the predicted RMST, press Suggest and see
the ghost spheres appear (mounted, on screen) and the suggestion's text; press Accept and see the predicted RMST the
page shows go down, the ghosts go and the new fiducials appear. Numbers are read from the page and compared with
the server's session (the page shows what the server holds)."""

from __future__ import annotations

import re

import pytest

from rrbc_core.session import planning_view
from rrbc_viz.serve import serve

from .helpers import canvas_rect, is_local_url, node_exists, node_screen_position, wait_for, wait_until_rendered

pytestmark = pytest.mark.browser

_RMST = re.compile(r"Predicted RMST: rigid ([0-9.]+) ± ([0-9.]+) mm, RRBC ([0-9.]+) ± ([0-9.]+) mm")


def page_rmst(page) -> tuple[float, ...] | None:
    """(rigid, std, RRBC, std) mm as the page's Plan tab shows them, or None if not shown."""
    m = _RMST.search(page.inner_text("body"))
    return tuple(float(x) for x in m.groups()) if m else None


def server_rmst(app) -> tuple[float, ...]:
    p = planning_view.planning_state(app.session).predicted
    return tuple(
        float(f"{x:.{3 if i % 2 == 0 else 4}f}")
        for i, x in enumerate((p.rigid_mm, p.rigid_std_mm, p.rrbc_mm, p.rrbc_std_mm))
    )


def test_plan_tab_suggest_shows_ghosts_and_accept_lowers_the_predicted_rmst(viser_app, page_for):
    app = viser_app(lambda: serve(simple_arm=True, plain_light=True))
    page, requests = page_for(app.url)
    wait_until_rendered(page, "/targets/H1/gizmo", timeout_s=60)

    page.get_by_role("tab", name="Plan", exact=True).click()
    page.get_by_text("Predicted RMST:", exact=False).first.wait_for(state="visible")
    before = page_rmst(page)
    assert before == server_rmst(app), (before, server_rmst(app))
    assert "8 of 8 targets" in page.inner_text("body")

    # Suggest (K = 4, the slider's default): the planner runs (a few seconds), ghosts appear in the 3-D view
    page.get_by_role("button", name="Suggest", exact=True).click()
    page.get_by_text("Suggested: 4 fiducials", exact=False).first.wait_for(state="visible", timeout=60_000)
    result = app.session.suggestion
    assert result is not None and len(result.suggested_ids) == 4
    wait_for(
        lambda: all(node_exists(page, f"/plan/ghosts/{i}") for i in range(4)),
        20,
        message="the four ghost spheres in the browser",
        page=page,
    )
    rect = canvas_rect(page)

    def ghosts_in_view() -> bool:  # each ghost projects into the 3-D view (once the server has framed the tab)
        for i in range(4):
            x, y = node_screen_position(page, f"/plan/ghosts/{i}")
            if not (rect["x"] < x < rect["x"] + rect["width"] and rect["y"] < y < rect["y"] + rect["height"]):
                return False
        return True

    wait_for(ghosts_in_view, 20, message="the four ghosts inside the 3-D view", page=page)
    body = page.inner_text("body")
    assert all(cid in body for cid in result.suggested_ids)
    assert f"{result.predicted_after.rrbc_mm:.3f}" in body  # the predicted gain, said before accepting
    assert page_rmst(page) == before  # nothing changed yet

    # Accept: the predicted RMST the page shows goes down; ghosts go, the new fiducials are there
    page.get_by_role("button", name="Accept suggestions", exact=True).click()
    wait_for(lambda: page_rmst(page) not in (None, before), 20, message="the predicted RMST to change", page=page)
    after = page_rmst(page)
    assert after == server_rmst(app), (after, server_rmst(app))
    assert after[2] < before[2], (before, after)  # RRBC
    wait_for(lambda: not node_exists(page, "/plan/ghosts/0"), 20, message="the ghosts to go", page=page)
    for cid in result.suggested_ids:
        assert node_exists(page, f"/fiducials/{cid}/gizmo/sphere"), cid
    assert "Fiducials added" in page.inner_text("body")  # the notification
    assert not [u for u in requests if not is_local_url(u, app.port)]
