"""A measured file with stations in the explorer session (issue 28, item 1): one station open at a time, as a file
of its own, with the pooled figures of `rrbc correct`."""

import pytest

from rrbc_core.correction.pipeline import correct_measurements
from rrbc_core.correction.stations import correct_stations
from rrbc_core.errors import InputError
from rrbc_core.io.groups import split_groups
from rrbc_core.session.explorer import ExplorerSession
from rrbc_core.simulation.station_data import station_measurements


def test_a_station_opens_as_the_file_of_its_rows():
    mset = station_measurements(31, stations=3, eval_fiducials=0.5)
    parts = dict(split_groups(mset))
    session = ExplorerSession.from_measurements(mset)
    assert session.stations == ("station1", "station2", "station3") and session.station == "station1"
    second = ExplorerSession.from_measurements(mset, station="station2")
    ev = second.evaluate()
    alone = correct_measurements(parts["station2"])
    assert ev.registration.fre_rms_mm == pytest.approx(alone.registration.fre_rms_mm)
    assert set(ev.targets.ids) == set(alone.checks.ids) and ev.warnings == alone.warnings()


def test_the_pooled_figures_are_rrbc_corrects():
    mset = station_measurements(32, stations=3, eval_fiducials=0.5)
    session = ExplorerSession.from_measurements(mset, station="station3")
    session.update(interpolation="tps")
    s = session.stations_summary()
    expected = correct_stations(mset, session.settings.method).summary()
    assert s["rmst_rrbc_mm"] == pytest.approx(expected["rmst_rrbc_mm"]) and s["checks"] == expected["checks"]


def test_an_unknown_station_is_refused_with_the_known_ones():
    mset = station_measurements(33, stations=2)
    with pytest.raises(InputError, match="no station 'x'.*station1, station2"):
        ExplorerSession.from_measurements(mset, station="x")
    plain = station_measurements(33, stations=2, group_column=False)
    with pytest.raises(InputError, match="no group column"):
        ExplorerSession.from_measurements(plain, station="station1")
    assert ExplorerSession.from_measurements(plain).stations == ()
