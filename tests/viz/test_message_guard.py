"""Malformed and hostile messages (issue 31, item 4; rrbc_viz.message_guard): a real server and raw websocket
clients. Garbage and wrongly typed messages are dropped without a traceback, logged at most once a minute per
client, a client that keeps sending them is disconnected, the other tabs keep working, and well-formed messages (a
drag) still reach the app."""

from __future__ import annotations

import os
import time

import numpy as np
import pytest

from rrbc_viz import message_guard
from tests.support.viser_clients import ClientPool, encode


@pytest.fixture
def pool(app):
    p = ClientPool(app.url, 2)
    try:
        yield p
    finally:
        p.close()


def _garbage(k: int) -> bytes:
    return [
        os.urandom(48),
        encode("TransformControlsUpdateMessage", name=5, wxyz="x", position=None),
        encode("NoSuchMessage", a=1),
        encode("TransformControlsUpdateMessage", name="/targets/H1/gizmo", wxyz=[1, 0, 0, 0], position=[1, 2]),
        b"\x81\xa4type\xc0",  # a map whose type is nil
    ][k % 5]


def test_malformed_messages_are_dropped_logged_once_and_a_flood_disconnects(app, pool, capfd):
    before = dict(message_guard.stats)
    for k in range(message_guard.MAX_BAD):
        pool.send_raw(1, _garbage(k))
    time.sleep(1.0)
    assert not pool.records[1].closed  # up to the limit: dropped, still connected
    assert message_guard.stats["dropped"] - before["dropped"] == message_guard.MAX_BAD
    err = capfd.readouterr().err
    assert err.count("malformed message(s) from a client") == 1 and "Traceback" not in err, err
    pool.send_raw(1, _garbage(0))  # one more within the minute: disconnected
    deadline = time.monotonic() + 10
    while not pool.records[1].closed and time.monotonic() < deadline:
        time.sleep(0.1)
    assert pool.records[1].closed and pool.records[1].close_code == 1008
    assert not pool.records[0].closed  # the other tab is still served
    # another tab from the same address: its own malformed message is dropped, it is not closed for the first tab's
    # flood, and the address's log line is not repeated within the minute
    before = message_guard.stats["dropped"]
    pool.send_raw(0, _garbage(2))
    deadline = time.monotonic() + 10
    while message_guard.stats["dropped"] == before and time.monotonic() < deadline:
        time.sleep(0.05)
    assert message_guard.stats["dropped"] == before + 1 and not pool.records[0].closed
    assert "malformed message(s) from a client" not in capfd.readouterr().err


def test_well_formed_messages_still_drive_the_app(app, pool):
    """A drag sent by a raw client passes the check: the target moves on the server."""
    p0 = np.array(app.session.layout["targets"].positions[0], float)
    goal = p0 + [30.0, 0.0, 0.0]
    pool.drag_all(["/targets/H1/gizmo"], lambda k, t: goal, seconds=0.6)
    assert app.evaluate.wait_drags(20.0)
    np.testing.assert_allclose(app.session.layout["targets"].positions[0], goal, atol=1e-6)


def test_the_check_names_what_is_wrong():
    from viser.infra._messages import Message

    assert message_guard.check(encode("NoSuchMessage"), Message)[1].startswith("unknown message type")
    assert "not MessagePack" in message_guard.check(b"\xc1", Message)[1]
    ok, why = message_guard.check(
        encode("TransformControlsDragStartMessage", name="/targets/H1/gizmo", owner=""), Message
    )
    assert ok is not None and why == ""


def test_hostile_gui_values_are_dropped_without_a_traceback_and_good_ones_still_apply(app, pool, capfd):
    """Issue 42, item 2: well-formed GUI updates with hostile values for real widgets - text for a slider, a
    property a client may not set, NaN, infinity, out of range, a dropdown choice not offered - change nothing and
    log no traceback; a valid update from the same client still applies."""
    explore = app.controls.explore
    slider, menu = explore.noise, explore.interpolation
    top = slider._impl.props.max
    hostile = [
        (slider, {"value": "abc"}),
        (slider, {"nope": 1}),
        (slider, {"value": float("nan")}),
        (slider, {"value": float("inf")}),
        (slider, {"value": top * 1e6}),
        (menu, {"value": "rm -rf"}),
        (menu, {"value": 5}),
        (menu, {"value": "x" * 20_000}),
    ]
    before = (slider.value, menu.value, message_guard.stats["dropped"])
    for handle, updates in hostile:
        pool.send_raw(0, encode("GuiUpdateMessage", uuid=handle._impl.uuid, updates=updates))
    good = min(top, 2.0)
    pool.send_raw(0, encode("GuiUpdateMessage", uuid=slider._impl.uuid, updates={"value": good}))
    deadline = time.monotonic() + 10
    while slider.value != good and time.monotonic() < deadline:
        time.sleep(0.05)
    assert slider.value == good and menu.value == before[1]  # only the good update applied, in order
    assert message_guard.stats["dropped"] - before[2] == len(hostile)
    err = capfd.readouterr().err
    assert "Traceback" not in err and "AssertionError" not in err, err
    assert not pool.records[0].closed


def test_the_gui_check_names_what_is_wrong():
    class Slider:
        value, min, max = 1.0, 0.0, 3.0

    class Menu:
        value, options = "idw", ("idw", "tps")

    assert message_guard.check_gui_update(Slider, {"value": 2.5}) == ""
    assert "finite" in message_guard.check_gui_update(Slider, {"value": float("nan")})
    assert "range" in message_guard.check_gui_update(Slider, {"value": 3.5})
    assert "property" in message_guard.check_gui_update(Slider, {"visible": False})
    assert message_guard.check_gui_update(Menu, {"value": "tps"}) == ""
    assert "options" in message_guard.check_gui_update(Menu, {"value": "gp"})


def test_the_widgets_the_app_uses_accept_what_a_browser_sends_for_them():
    """Real viser widgets: a button group's click sends the option's text (the View tab's camera presets were dropped
    as 'not a true/false value': viser marks a button group as a button), a button's and a checkbox's a boolean,
    a dropdown's one of its options."""
    import viser

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        gui = server.gui
        group = gui.add_button_group("Camera", ("whole cell", "close-up"))
        button, box = gui.add_button("Go"), gui.add_checkbox("On", False)
        menu = gui.add_dropdown("Interpolation", ("idw", "tps"))
        ok = [(group, "close-up"), (button, True), (box, True), (menu, "tps")]
        assert all(message_guard.check_gui_update(h._impl, {"value": v}) == "" for h, v in ok)
        bad = [(group, "nope"), (group, True), (button, "close-up"), (box, "yes"), (menu, "gp")]
        assert all(message_guard.check_gui_update(h._impl, {"value": v}) for h, v in bad)
    finally:
        server.stop()
