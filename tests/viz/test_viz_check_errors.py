"""A measurement file's check rows show their errors on the first view (issue 39, item 4): from each check an arrow
along the error of the position the robot is sent to, magnified as the correction arrows are, coloured by size, the
largest labelled with the numbers the card and the table give; switchable between RRBC and rigid; a layer."""

import numpy as np
import pytest

from rrbc_core.errors import InputError
from rrbc_viz import colors
from rrbc_viz.node_values import CHECK_ERROR_LABELS, CHECK_ERROR_SHARE, legible_magnification


def _drawn(app):
    arrows = app.nodes.handle("/check_errors/arrows")
    seg = np.asarray(arrows.points, float)
    return seg, np.asarray(arrows.colors)


def test_each_check_row_draws_its_error_coloured_by_size_and_the_largest_are_labelled(measured):
    app = measured
    ev = app.session.last
    t = ev.targets
    rows = [i for i, pid in enumerate(t.ids) if pid in ev.check_ids]
    assert len(rows) > CHECK_ERROR_LABELS
    for method, landed, sizes in (("rrbc", t.robot_rrbc, t.error_rrbc), ("rigid", t.robot_rigid, t.error_rigid)):
        app.evaluate.set_display(check_error=method)
        ev = app.session.last
        seg, rgb = _drawn(app)
        assert seg.shape == (len(rows), 2, 3)
        mag = legible_magnification(
            float(np.max(sizes[rows])), CHECK_ERROR_SHARE * app.state.extent_mm, app.state.display.magnification
        )
        np.testing.assert_allclose(seg[:, 0], t.positions[rows], atol=1e-3)
        np.testing.assert_allclose(seg[:, 1] - seg[:, 0], mag * (landed[rows] - t.truth[rows]), atol=1e-2)
        # the drawn length is the error the card and the table give, times the magnification
        np.testing.assert_allclose(np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1) / mag, sizes[rows], rtol=1e-5)
        # coloured by size: the largest at the scale's top, the colours following the sizes' order on the scale
        top = int(np.argmax(sizes[rows]))
        assert tuple(rgb[top, 0]) == tuple(colors.scale_colors([1.0], 0.0, 1.0)[0])
        expect = colors.scale_colors(sizes[rows], 0.0, float(np.max(sizes[rows])))
        np.testing.assert_array_equal(rgb[:, 0], expect)
        # the largest few labelled with their id and size, at their arrow's tip
        largest = np.argsort(-sizes[rows])[:CHECK_ERROR_LABELS]
        for k, i in enumerate(largest):
            label = app.nodes.handle(f"/check_errors/label{k}")
            assert label.text.startswith(f"{t.ids[rows[i]]}: {sizes[rows[i]]:.3f} mm")
            assert f"({'RRBC' if method == 'rrbc' else 'rigid'}, ×{mag:g})" in label.text
            np.testing.assert_allclose(label.position, seg[i, 1], atol=1e-2)
    # a layer: off hides the group, on shows it again
    app.evaluate.set_layer("check_errors", False)
    assert not app.nodes.handle("/check_errors").visible
    app.evaluate.set_layer("check_errors", True)
    assert app.nodes.handle("/check_errors").visible
    with pytest.raises(InputError, match="check_error must be one of"):
        app.evaluate.set_display(check_error="vec")


def test_a_scene_without_check_rows_draws_no_check_errors(app):
    assert app.session.last.check_ids == frozenset()
    assert app.nodes.handle("/check_errors/arrows") is None


def test_the_magnification_keeps_the_longest_arrow_within_its_share_of_the_view():
    """Millimetre errors on a station metres wide: the arrows' magnification where it fits, else the largest 1-2-5
    value that does (never below 1)."""
    assert legible_magnification(0.4, 150.0, 200.0) == 200.0  # 80 mm: fits
    assert legible_magnification(7.0, 600.0, 200.0) == 50.0  # 1400 mm would not; 350 mm does
    assert legible_magnification(3.0, 600.0, 200.0) == 200.0
    assert legible_magnification(10.0, 5.0, 200.0) == 1.0  # never below true size
    for largest, length in ((0.013, 7.0), (6.8, 900.0), (123.0, 4000.0)):
        m = legible_magnification(largest, length, 500.0)
        assert largest * m <= length + 1e-9 and (m == 500.0 or largest * m * 2.5 > length)
