"""Camera framing (rrbc_core.geometry.framing): every point inside the window left free by the panel, and no
closer camera along the same axis would do (the framing is tight)."""

import numpy as np
import pytest

from rrbc_core.errors import InputError
from rrbc_core.geometry.framing import CameraPose, camera_basis, frame_points, in_view, project


@pytest.mark.parametrize("seed", range(12))
def test_framed_points_lie_inside_the_free_window_and_the_framing_is_tight(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 40))
    pts = rng.normal(0, rng.uniform(1, 500), (n, 3)) + rng.uniform(-1000, 1000, 3)
    direction = rng.normal(size=3)
    fov = rng.uniform(0.3, 1.5)
    aspect = rng.uniform(0.6, 2.2)
    panel = rng.uniform(0.0, 0.45)
    margin = 0.08
    pose = frame_points(pts, direction, fov, aspect, panel_fraction=panel, margin=margin, min_distance=1.0)
    ndc, depth = project(pts, pose)
    assert np.all(depth >= 1.0 - 1e-6)
    x_hi = 1 - 2 * panel
    half = 0.5 * (x_hi + 1)
    tol = 1e-6
    assert np.all(ndc[:, 0] >= -1 + margin * half - tol) and np.all(ndc[:, 0] <= x_hi - margin * half + tol)
    assert np.all(np.abs(ndc[:, 1]) <= 1 - margin + tol)
    # tight: some point touches an edge of the window (or the nearest-distance limit)
    edges = np.concatenate(
        [
            np.abs(ndc[:, 0] - (-1 + margin * half)),
            np.abs(ndc[:, 0] - (x_hi - margin * half)),
            np.abs(np.abs(ndc[:, 1]) - (1 - margin)),
            np.abs(depth - 1.0) / 1000,
        ]
    )
    assert edges.min() < 1e-5
    # centred: the points' extent sits in the middle of the window in both directions (the slack one included)
    assert abs(0.5 * (ndc[:, 0].min() + ndc[:, 0].max()) - 0.5 * (-1 + x_hi)) < 0.05
    assert abs(0.5 * (ndc[:, 1].min() + ndc[:, 1].max())) < 0.05
    # stepping 1 % closer along the axis pushes some point out of the window
    f = pose.forward
    closer = CameraPose(pose.position + 0.01 * depth.max() * f, pose.look_at, pose.up, fov, aspect)
    ndc2, depth2 = project(pts, closer)
    outside = (
        (ndc2[:, 0] < -1 + margin * half - tol)
        | (ndc2[:, 0] > x_hi - margin * half + tol)
        | (np.abs(ndc2[:, 1]) > 1 - margin + tol)
        | (depth2 < 1.0)
    )
    assert outside.any()
    # the look-at point is on the optical axis, in front of the camera
    d = pose.look_at - pose.position
    np.testing.assert_allclose(d / np.linalg.norm(d), camera_basis(direction)[0], atol=1e-12)


@pytest.mark.parametrize("seed", range(6))
def test_a_top_margin_keeps_room_above_the_points_and_the_framing_tight(seed):
    """`top_margin`: no point above 1 - top_margin (room for labels over the top points), the bottom keeps
    `margin`, and the points are still as close as the window allows (some point on an edge, vertically centred in
    the narrower window)."""
    rng = np.random.default_rng(100 + seed)
    pts = rng.normal(0, rng.uniform(10, 500), (int(rng.integers(2, 30)), 3))
    direction, fov, aspect = rng.normal(size=3), rng.uniform(0.4, 1.2), rng.uniform(0.8, 2.0)
    margin, top = 0.08, rng.uniform(0.1, 0.4)
    ndc, _ = project(pts, frame_points(pts, direction, fov, aspect, margin=margin, top_margin=top))
    tol = 1e-6
    assert np.all(ndc[:, 1] <= 1 - top + tol) and np.all(ndc[:, 1] >= -1 + margin - tol)
    assert abs(0.5 * (ndc[:, 1].min() + ndc[:, 1].max()) - 0.5 * (margin - top)) < 0.05
    on_edge = np.concatenate(
        [np.abs(ndc[:, 1] - (1 - top)), np.abs(ndc[:, 1] + 1 - margin), np.abs(np.abs(ndc[:, 0]) - (1 - margin))]
    )
    assert on_edge.min() < 1e-5
    with pytest.raises(InputError):
        frame_points(pts, direction, fov, aspect, top_margin=1.0)


def test_a_panel_shifts_the_points_left():
    pts = np.array([[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [0.0, 100.0, 50.0]])
    free = project(pts, frame_points(pts, [0, 1, -0.5], 0.9, 1.6, panel_fraction=0.0))[0]
    panel = project(pts, frame_points(pts, [0, 1, -0.5], 0.9, 1.6, panel_fraction=0.3))[0]
    assert panel[:, 0].max() <= 1 - 0.6 and free[:, 0].max() > panel[:, 0].max()


def test_bad_framing_input_is_refused():
    with pytest.raises(InputError):
        frame_points(np.zeros((0, 3)), [0, 1, 0], 0.9, 1.6)
    with pytest.raises(InputError):
        frame_points(np.zeros((2, 3)), [0, 0, 0], 0.9, 1.6)
    with pytest.raises(InputError):
        frame_points(np.zeros((2, 3)), [0, 1, 0], 4.0, 1.6)


def test_in_view_is_what_the_framing_framed_and_nothing_behind_or_under_the_panel():
    rng = np.random.default_rng(4)
    pts = rng.uniform(-200, 200, (30, 3))
    pose = frame_points(pts, np.array([-0.3, 1.0, -0.7]), np.deg2rad(50), 1.6, panel_fraction=0.3)
    assert in_view(pts, pose, 0.3).all()  # framed: every point beside the panel
    f, r, u = camera_basis(pose.forward, pose.up)
    depth = float((pts.mean(0) - pose.position) @ f)
    behind = pose.position - 100.0 * f
    tx = pose.aspect * np.tan(pose.fov_y / 2)
    under_panel = pose.position + depth * (f + 0.8 * tx * r)  # x_ndc = 0.8: under a panel over the right 30 %
    far_left = pose.position + depth * (f - 1.5 * tx * r)  # outside the image
    got = in_view(np.array([behind, under_panel, far_left]), pose, 0.3)
    assert not got.any(), got
    assert in_view(under_panel[None], pose, 0.0)[0]  # without the panel it is seen
