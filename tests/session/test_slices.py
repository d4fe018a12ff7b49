"""The error slice (rrbc_core.session.slices, rrbc_core.session.figures.error_slice): the plane's grid in the robot frame,
values that mean what they say (no bias and no noise: no error anywhere; at a fiducial: only that fiducial's own
noise is left), clear where the arm cannot reach, the hull flag against an independent hull test, and the story
it tells on the default scene (error grows outside the fiducials' hull)."""

import numpy as np
import pytest
from scipy.spatial import Delaunay

from rrbc_core.errors import InputError
from rrbc_core.io.scene import default_scene_path
from rrbc_core.io.scene_toml import load_scene
from rrbc_core.session import figures
from rrbc_core.session.explorer import ExplorerSession
from rrbc_core.session.slices import MAX_GRID, SlicePlane, default_plane


@pytest.fixture
def session():
    return ExplorerSession.from_scene(load_scene(default_scene_path()))


def test_the_grid_lies_on_the_plane_in_the_robot_frame():
    for axis, k in (("x", 0), ("y", 1), ("z", 2)):
        p = SlicePlane(axis, 12.5, (-10.0, 0.0), (30.0, 50.0), n=5)
        g = p.grid()
        assert g.shape == (5, 5, 3)
        assert np.all(g[..., k] == 12.5)
        a, b = [i for i in range(3) if i != k]
        assert g[..., a].min() == -10 and g[..., a].max() == 30 and g[..., b].min() == 0 and g[..., b].max() == 50
        assert np.all(np.diff(g[..., a], axis=1) > 0) and np.all(np.diff(g[..., b], axis=0) > 0)  # columns u, rows v


@pytest.mark.parametrize(
    "kwargs",
    [
        {"axis": "w"},
        {"lo": (0.0, 0.0), "hi": (0.0, 10.0)},
        {"n": 1},
        {"n": MAX_GRID + 1},
        {"offset_mm": float("nan")},
        {"lo": (0.0,)},
    ],
)
def test_bad_planes_are_refused(kwargs):
    base = {"axis": "z", "offset_mm": 0.0, "lo": (0.0, 0.0), "hi": (10.0, 10.0), "n": 4}
    with pytest.raises(InputError):
        SlicePlane(**{**base, **kwargs})


def test_without_bias_or_noise_nothing_is_wrong_anywhere(session):
    session.update(bias_scale=0.0, noise_scale=0.0)
    ev = session.last
    sl = figures.error_slice(session, default_plane(ev.targets.positions, "z", 15.0, n=12))
    reach = np.isfinite(sl.values["rigid"])
    assert reach.mean() > 0.9
    assert np.nanmax(sl.values["rigid"]) < 1e-6 and np.nanmax(sl.values["rrbc"]) < 1e-6


def test_at_a_fiducial_only_its_own_noise_is_left(session):
    """IDW is exact at a fiducial: the slice's RRBC error at a fiducial's place is the fiducial's reading noise
    carried through (sensor and robot noise of that one point), far below the rigid error there."""
    ev = session.last
    i = list(ev.fiducial_ids).index("F5")
    f = ev.fiducial_positions[i]
    plane = SlicePlane("z", float(f[2]), (f[0] - 50, f[1] - 50), (f[0] + 50, f[1] + 50), n=3)  # centre = F5
    sl = figures.error_slice(session, plane)
    np.testing.assert_allclose(sl.points[1, 1], f)
    e_rrbc, e_rigid = sl.values["rrbc"][1, 1], sl.values["rigid"][1, 1]
    noise = np.linalg.norm(ev.fiducial_readings.robot[i] - ev.fiducial_readings.truth[i])
    assert e_rrbc < 5 * max(noise, 0.02) and e_rrbc < 0.5 * e_rigid


def test_unreachable_points_are_clear_and_the_hull_flag_matches_an_independent_test(session):
    ev = session.last
    sl = figures.error_slice(session, SlicePlane("y", 0.0, (-200.0, -300.0), (1400.0, 1800.0), n=24))
    far = np.linalg.norm(sl.points, axis=-1) > 1500  # far beyond a UR5's ~950 mm (with its tool)
    assert far.any() and np.all(np.isnan(sl.values["rigid"][far])) and np.all(np.isnan(sl.values["rrbc"][far]))
    assert np.isfinite(sl.values["rigid"]).any()
    plane = default_plane(ev.fiducial_positions, "z", 30.0, margin=0.2, n=30)
    sl = figures.error_slice(session, plane)
    hull = Delaunay(ev.fiducial_positions[ev.included])
    inside = hull.find_simplex(sl.points.reshape(-1, 3)) >= 0
    # the slice tests the hull in sensor space (readings); away from its surface the two agree
    d = np.min(np.abs(hull.plane_distance(sl.points.reshape(-1, 3))), axis=1)
    clear = d > 5.0
    agree = sl.inside_hull.ravel()[clear] == inside[clear]
    assert agree.mean() > 0.97


def test_rrbc_error_grows_outside_the_fiducials_hull_on_the_default_scene(session):
    ev = session.last
    sl = figures.error_slice(session, default_plane(ev.fiducial_positions, "z", 15.0, margin=0.35, n=40))
    rrbc, rigid = sl.values["rrbc"], sl.values["rigid"]
    ok = np.isfinite(rrbc)
    inside, outside = ok & sl.inside_hull, ok & ~sl.inside_hull
    assert np.median(rrbc[inside]) < 0.5 * np.median(rrbc[outside])
    assert np.median(rrbc[inside]) < 0.5 * np.median(rigid[inside])  # RRBC helps inside
    before = rrbc.copy()
    session.move("fiducials", "F5", ev.fiducial_positions[list(ev.fiducial_ids).index("F5")] + [0, 0, 40])
    after = figures.error_slice(session, sl.plane).values["rrbc"]
    assert not np.allclose(np.nan_to_num(before), np.nan_to_num(after))  # the field follows the fiducials
