"""Driving the app as a browser would, through viser's own handlers (private API of viser 1.1.1, kept here)."""

from __future__ import annotations

import asyncio

import viser

from rrbc_viz.app import RunningApp


def _gizmo_drag(app: RunningApp, kind: str, pid: str, positions) -> None:
    """Drive a gizmo the way a browser does: drag-start, update messages, drag-end, through viser's handlers
    (private API of viser 1.1.1, kept in this one helper)."""
    from viser import _messages as msg

    name = app.evaluate.gizmo_name(kind, pid)
    scene = app.server.scene
    loop = app.server.get_event_loop()

    async def run():
        await scene._handle_transform_controls_drag_start(0, msg.TransformControlsDragStartMessage(name=name))
        for p in positions:
            await scene._handle_transform_controls_updates(
                0,
                msg.TransformControlsUpdateMessage(
                    name=name, wxyz=(1.0, 0.0, 0.0, 0.0), position=tuple(float(x) for x in p)
                ),
            )
        await scene._handle_transform_controls_drag_end(0, msg.TransformControlsDragEndMessage(name=name))

    asyncio.run_coroutine_threadsafe(run(), loop).result(timeout=20)
    assert app.evaluate.wait_drags(20.0), "the drag events were not handled in time"


def _press(button) -> None:
    """Call a GUI button's click callbacks as viser would for a press (private API of viser 1.1.1)."""
    entries = button._impl.update_cb
    assert entries, "the button has no click callback"
    for cb in entries:
        cb(viser.GuiEvent(client=None, client_id=None, target=button))
