"""Warnings on a correction (issue 28): wild corrections, conflicting nearly coincident fiducials, extrapolation."""

import numpy as np
import pytest

from rrbc_core.correction.pipeline import correct_measurements
from rrbc_core.correction.warnings import (
    WILD_FACTOR,
    Corrected,
    conflicting_fiducials,
    correction_warnings,
    wild_corrections,
)
from rrbc_core.interpolation.hull import assess_coverage
from rrbc_core.io.measurements import read_measurements
from rrbc_core.methods import MethodOptions
from rrbc_core.simulation.station_data import station_measurements
from tests.paths import EXAMPLE_CSV


def test_a_wild_correction_is_named_with_its_size_and_point():
    rng = np.random.default_rng(0)
    e = rng.normal(0, 1, (10, 3))
    largest = np.linalg.norm(e, axis=1).max()
    corr = rng.normal(0, 0.1, (5, 3))
    assert wild_corrections(e, Corrected("check", list("abcde"), corr, None)) is None
    corr[3] = [0, 0, WILD_FACTOR * largest * 1.01]
    w = wild_corrections(e, Corrected("check", list("abcde"), corr, None))
    assert w is not None and "1 of 5 checks" in w and "'d'" in w and f"{largest:.2f} mm" in w


def test_conflicting_twins_are_named_and_agreeing_twins_are_not():
    rng = np.random.default_rng(1)
    pts = rng.uniform(-300, 300, (20, 3))
    e = np.tile([1.0, 0.0, 0.0], (20, 1)) + rng.normal(0, 0.02, (20, 3))
    ids = [f"F{i}" for i in range(22)]
    twins = np.vstack([pts, pts[[2, 7]] + [0.1, 0, 0]])
    agree = np.vstack([e, e[[2, 7]] + 0.01])
    assert conflicting_fiducials(ids, twins, agree) is None
    conflict = agree.copy()
    conflict[20] += [0, 3.0, 0]
    w = conflicting_fiducials(ids, twins, conflict)
    assert w is not None and w.startswith("1 pair") and "'F2' and 'F20'" in w


def test_pooled_stations_warn_of_their_conflicting_fiducials_and_grouped_ones_do_not():
    """A file that pools stations holds the board's points once per station with different corrections."""
    pooled = station_measurements(4, stations=3, group_column=False)
    warnings = correct_measurements(pooled).warnings()
    assert any("nearly coincident fiducials" in w for w in warnings)
    from rrbc_core.correction.stations import correct_stations

    grouped = correct_stations(station_measurements(4, stations=3))
    assert not any("nearly coincident" in w for w in grouped.warnings())


def test_checks_off_the_fiducials_plane_are_counted_with_their_distances():
    mset = station_measurements(2, stations=1, group_column=False)
    result = correct_measurements(mset)
    cov = assess_coverage(result.fiducials.sensor, result.checks.sensor)
    off = cov.off_plane_mm[cov.off_plane_mm > cov.plane_tol_mm]
    [w] = [w for w in result.warnings() if "outside the fiducials' hull" in w]
    assert f"{int((~cov.inside).sum())} of {len(result.checks.ids)} checks" in w
    assert f"{off.min():.0f}–{off.max():.0f} mm (median {np.median(off):.0f} mm)" in w


def test_the_example_file_is_quiet():
    """Fiducials around the checks, no twins: nothing to warn of."""
    result = correct_measurements(read_measurements(EXAMPLE_CSV))
    assert not any("nearly coincident" in w or "above" in w for w in result.warnings())


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("method", ["idw", "linear", "tps", "gp"])
def test_every_correction_beyond_the_bound_is_warned(seed, method):
    """Real-like pooled files push the exact interpolators hardest; whatever a method predicts, a correction beyond
    WILD_FACTOR × the largest fiducial correction never goes without its warning."""
    mset = station_measurements(seed, stations=4, eval_fiducials=0.5, group_column=False)
    result = correct_measurements(mset, MethodOptions.named("least-squares", method))
    largest = np.linalg.norm(result.fiducial_corrections, axis=1).max()
    wild = np.linalg.norm(result.checks_corrected.correction, axis=1) > WILD_FACTOR * largest
    assert any("above" in w for w in result.warnings()) == bool(wild.any())


def test_warnings_are_in_the_json_and_in_the_text():
    from rrbc_core.cli_text import correct_text

    result = correct_measurements(station_measurements(5, stations=2, group_column=False))
    assert result.to_json()["warnings"] == list(result.warnings()) and result.warnings()
    text = correct_text(result)
    for w in result.warnings():
        assert f"warning: {w}" in text


def test_no_points_no_warnings():
    assert correction_warnings([], np.zeros((0, 3)), np.zeros((0, 3)), []) == ()
