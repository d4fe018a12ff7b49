"""A measured file with stations in the browser (issue 28): the File tab's Station menu opens another station, and
the Explore summary says which one is open with the pooled figures of `rrbc correct`."""

from __future__ import annotations

import pytest

from rrbc_core.io.measurements_write import write_measurements
from rrbc_core.simulation.station_data import station_measurements
from rrbc_viz.serve import serve

from .helpers import wait_for

pytestmark = pytest.mark.browser


def test_the_station_menu_opens_another_station(viser_app, page_for, tmp_path):
    path = tmp_path / "stations.csv"
    write_measurements(path, station_measurements(51, stations=3, eval_fiducials=0.5))
    app = viser_app(lambda: serve(path, port=0, plain_light=True))
    page, _ = page_for(app.url)
    text = page.get_by_text("Station station1 of 3", exact=False).first  # the Explore summary
    text.wait_for(state="visible", timeout=30_000)
    pooled = app.session.stations_summary()
    assert f"{pooled['rmst_rigid_mm']:.3f} mm rigid" in text.inner_text()
    page.get_by_role("tab", name="File").click()
    menu = page.get_by_label("Station")
    menu.wait_for(state="visible", timeout=15_000)
    menu.click()
    page.get_by_role("option", name="station2", exact=True).click()
    wait_for(lambda: app.session.station == "station2", 30, message="station2 opened", page=page)
    page.get_by_role("tab", name="Explore").click()
    page.get_by_text("Station station2 of 3", exact=False).first.wait_for(state="visible", timeout=30_000)
    assert "station 'station2' (2 of 3)" in app.loaded.label
