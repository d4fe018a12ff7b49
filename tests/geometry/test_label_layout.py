"""Lesson labels laid out without overlaps (rrbc_core.geometry.label_layout): seeded random labels in a camera's
view; the kept boxes never meet, the first is kept when it fits, nothing is kept under the panel or behind the
camera, and labels far apart are all kept."""

from __future__ import annotations

import numpy as np
import pytest

from rrbc_core.geometry.framing import CameraPose, frame_points
from rrbc_core.geometry.label_layout import GAP_PX, label_boxes, uncluttered

IMAGE = (1280.0, 720.0)


def _pose(points) -> CameraPose:
    return frame_points(points, np.array([-0.25, 1.0, -0.75]), np.deg2rad(50.0), IMAGE[0] / IMAGE[1])


@pytest.mark.parametrize("seed", range(5))
def test_kept_labels_never_meet_and_stay_left_of_the_panel(seed):
    rng = np.random.default_rng(seed)
    pts = rng.uniform([0, -300, 0], [600, 300, 50], (int(rng.integers(5, 40)), 3))
    texts = [f"F{i + 1} · e {rng.uniform(0, 1):.3f} mm" for i in range(len(pts))]
    panel = float(rng.choice([0.0, 400.0, 560.0]))
    pose = _pose(pts)
    boxes = label_boxes(
        pts, texts, pose, IMAGE, float(rng.choice([0.75, 2.0])), str(rng.choice(["bottom-left", "bottom-center"]))
    )
    keep = uncluttered(boxes, IMAGE, panel)
    k = boxes[keep]
    assert len(k) >= 1
    assert (
        np.all(k[:, 0] >= 0)
        and np.all(k[:, 2] <= IMAGE[0] - panel)
        and np.all(k[:, 1] >= 0)
        and np.all(k[:, 3] <= IMAGE[1])
    )
    for i in range(len(k)):
        for j in range(i + 1, len(k)):
            a, b = k[i], k[j]
            apart = a[2] + GAP_PX <= b[0] or b[2] + GAP_PX <= a[0] or a[3] + GAP_PX <= b[1] or b[3] + GAP_PX <= a[1]
            assert apart, (a, b)
    # every label not kept meets a kept one or leaves the free part of the image
    for box in boxes[~keep]:
        outside = box[0] < 0 or box[1] < 0 or box[2] > IMAGE[0] - panel or box[3] > IMAGE[1]
        meets = any(
            box[0] < c[2] + GAP_PX and c[0] < box[2] + GAP_PX and box[1] < c[3] + GAP_PX and c[1] < box[3] + GAP_PX
            for c in k
        )
        assert outside or meets


def test_the_first_label_wins_far_labels_all_stay_and_none_behind_the_camera():
    pts = np.array([[300.0, 0.0, 0.0], [300.5, 0.0, 0.0], [300.0, 250.0, 0.0], [600.0, -250.0, 0.0]])
    pose = _pose(pts)
    texts = ["H1 · rigid 0.738", "H2 · rigid 0.692", "H3", "H4"]
    keep = uncluttered(label_boxes(pts, texts, pose, IMAGE, 0.75), IMAGE)
    assert keep.tolist() == [True, False, True, True]  # H2 sits on H1: the first named keeps its label
    order = [1, 0, 2, 3]
    keep = uncluttered(label_boxes(pts[order], [texts[i] for i in order], pose, IMAGE, 0.75), IMAGE)
    assert keep.tolist() == [True, False, True, True]
    behind = pose.position - 100.0 * pose.forward
    boxes = label_boxes(np.vstack([pts, behind]), texts + ["B"], pose, IMAGE, 0.75)
    assert np.isnan(boxes[-1]).all() and not uncluttered(boxes, IMAGE)[-1]


def test_a_label_that_would_meet_a_placed_one_takes_its_first_free_other_anchor():
    """`placed`: each label in order takes its first candidate box that is in the image and meets no box placed
    before; one whose every candidate is taken is hidden (-1)."""
    from rrbc_core.geometry.label_layout import placed

    nan = [np.nan] * 4
    cand = np.array(
        [
            [[100, 100, 200, 110], nan, nan],  # placed with its own anchor
            [[150, 100, 250, 110], [150, 112, 250, 122], nan],  # its own meets the first: the second candidate
            [[150, 100, 250, 110], [150, 112, 250, 122], [-10, 100, 90, 110]],  # both taken, the third off screen
            [[300, 300, 400, 310], [0, 0, 10, 10], nan],  # its own is free
        ],
        float,
    )
    assert placed(cand, IMAGE).tolist() == [0, 1, -1, 0]
    assert uncluttered(cand[:, 0], IMAGE).tolist() == [True, False, False, True]


def test_a_spheres_box_holds_its_disc_as_a_pinhole_camera_draws_it():
    """A sphere of radius r straight ahead at distance d spans 2 r f / d px (f = h / 2 / tan(fov / 2)) about the
    image's centre; one off-axis is centred where its centre projects; one behind the camera has no box."""
    from rrbc_core.geometry.label_layout import sphere_boxes

    fov, image = np.deg2rad(50.0), (1280, 720)
    pose = CameraPose(np.zeros(3), np.array([0.0, 1000.0, 0.0]), np.array([0.0, 0.0, 1.0]), fov, 1280 / 720)
    boxes = sphere_boxes(
        [[0.0, 1000.0, 0.0], [100.0, 2000.0, 50.0], [0.0, -500.0, 0.0]], [10.0, 20.0, 5.0], pose, image
    )
    f = 360.0 / np.tan(fov / 2.0)
    np.testing.assert_allclose(
        boxes[0], [640 - 10 * f / 1000, 360 - 10 * f / 1000, 640 + 10 * f / 1000, 360 + 10 * f / 1000]
    )
    centre = label_boxes([[100.0, 2000.0, 50.0]], [""], pose, image, 1.0)[0]  # (its left and bottom: the point)
    np.testing.assert_allclose(0.5 * (boxes[1, 0] + boxes[1, 2]), centre[0])
    np.testing.assert_allclose(boxes[1, 2] - boxes[1, 0], 2 * 20 * f / 2000)
    assert np.all(np.isnan(boxes[2]))
