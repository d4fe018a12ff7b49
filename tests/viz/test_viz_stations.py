"""The app on a file with stations (issue 28): the File tab's Station menu, one station at a time, pooled figures."""

from rrbc_core.io.measurements_write import write_measurements
from rrbc_core.simulation.station_data import station_measurements
from rrbc_viz.serve import serve


def test_the_station_menu_opens_each_station_and_the_summary_gives_the_pool(tmp_path):
    path = tmp_path / "stations.csv"
    write_measurements(path, station_measurements(41, stations=3, eval_fiducials=0.5))
    app = serve(path, port=0)
    try:
        menu = app.controls.file.station
        assert menu.visible and tuple(menu.options) == ("station1", "station2", "station3")
        assert app.session.station == "station1"
        assert app.files.load_station("station2")
        assert app.session.station == "station2" and menu.value == "station2"
        assert "station 'station2' (2 of 3)" in app.loaded.label
        pooled = app.session.stations_summary()
        assert pooled is not None and pooled["stations"] == 3
        summary = app.controls.explore.summary.content
        assert "Station **station2** of 3" in summary
        assert f"{pooled['rmst_rigid_mm']:.3f} mm rigid → {pooled['rmst_rrbc_mm']:.3f} mm RRBC" in summary
        assert not app.files.load_station("nope")
        assert app.session.station == "station2"
    finally:
        app.stop()


def test_a_file_without_stations_hides_the_menu():
    app = serve(port=0)
    try:
        assert not app.controls.file.station.visible
    finally:
        app.stop()
