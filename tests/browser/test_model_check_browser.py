"""The Model tab in headless Chromium, as a user sees it (issue 36, item 4): open the tab, pick a measurement file the
app offers, press Check and read the predicted ranges beside the measured figures and the unexplained effect; the
3-D view draws the compared rows; press Extend the model and read that the extended scene is loaded and what it
gains out of sample. Numbers are read from the page and compared with the server's check."""

from __future__ import annotations

import dataclasses

import pytest

from rrbc_core.io.measurements_write import write_measurements
from rrbc_core.io.scene_toml import load_scene
from rrbc_core.models.errorterms import SmoothField
from rrbc_core.simulation.datasets import measured_data
from rrbc_core.simulation.montecarlo import work_cell_from_scene
from rrbc_viz.serve import serve
from tests.paths import DEMO

from .helpers import node_exists, wait_for, wait_until_rendered

pytestmark = pytest.mark.browser


def test_the_model_tab_checks_names_draws_and_extends(viser_app, page_for, tmp_path):
    scene = load_scene(DEMO)
    planted = scene.error_model.extended(robot=[SmoothField(rms_mm=0.4, length_mm=250.0, seed=2)])
    cell = work_cell_from_scene(dataclasses.replace(scene, error_model=planted), seed=0)
    write_measurements(tmp_path / "measured.csv", measured_data(cell, 5))
    app = viser_app(lambda: serve(DEMO, simple_arm=True, plain_light=True, data_dirs=[tmp_path]))
    page, _ = page_for(app.url)
    wait_until_rendered(page, "/targets/H1/gizmo", timeout_s=60)

    page.get_by_role("tab", name="Model", exact=True).click()
    page.get_by_role("button", name="Check the scene's model", exact=True).wait_for(state="visible")
    page.get_by_label("Measurement file").click()
    page.get_by_role("option", name=f"{tmp_path.name}/measured.csv").click()
    page.get_by_role("button", name="Check the scene's model", exact=True).click()
    page.get_by_text("unexplained by the model", exact=False).first.wait_for(state="visible", timeout=120_000)
    body = page.inner_text("body")
    r = app.state.model_check
    assert r is not None
    iv, measured = r.predicted["rmst_rigid_mm"], r.measured["rmst_rigid_mm"]
    assert f"{measured:.4g}" in body and f"{iv.lo95:.4g}" in body and f"{iv.hi95:.4g}" in body
    assert "OUTSIDE" in body and "smooth_field" in body
    wait_for(
        lambda: node_exists(page, "/model_check/outside"), 20, message="the rows outside in the 3-D view", page=page
    )

    page.get_by_role("button", name="Extend the model", exact=True).click()
    page.get_by_text("Extended model loaded", exact=False).first.wait_for(state="visible", timeout=120_000)
    g = r.gain
    body = page.inner_text("body")
    assert f"{g['prediction_error_before_mm']:.3g}" in body and f"{g['prediction_error_after_mm']:.3g}" in body
    assert "sampled_field" in [t.kind for t in app.session.scene.error_model.robot]
