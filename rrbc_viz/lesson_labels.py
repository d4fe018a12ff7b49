"""A lesson step's point labels without overlaps: those that would meet another label or run under the panel in
a tab's view are hidden (the named point's first). The layout is the core's (`rrbc_core.geometry.label_layout`);
here the scene's labels are read: their texts and where they are drawn."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from rrbc_core.geometry.label_layout import label_boxes, uncluttered

from .node_values import gizmo_name

if TYPE_CHECKING:
    from .nodes import SceneNodes


def label_anchor(nodes: SceneNodes, name: str) -> np.ndarray:
    """Where label `name` is drawn (robot frame, mm): its position, under its point's handle if it has one."""
    p = np.asarray(nodes.labels[name].position, float)
    parent = name.rsplit("/", 1)[0]
    if parent.endswith("/gizmo"):
        kind, pid = parent.strip("/").split("/")[:2]
        tc = nodes.gizmos.get((kind, pid))
        if tc is not None:
            p = p + np.asarray(tc.position, float)
    return p


def declutter(nodes: SceneNodes, pose, image_px, panel_px: float) -> frozenset[str]:
    """Hide the lesson step's labels that would overlap another or run under the panel when seen by `pose` (a
    `CameraPose`) in an image of `image_px` (width, height) CSS px: the selected point's label first, then in
    the file's order. Returns the names hidden."""
    lesson = tuple(f"/{k}/" for k in nodes.lesson_labels)
    names = [n for n in nodes.labels if n.startswith(lesson)]
    mine = None if nodes.selected is None else f"{gizmo_name(*nodes.selected)}/label"
    if mine in names:
        names.remove(mine)
        names.insert(0, mine)
    hidden: frozenset[str] = frozenset()
    if names:
        anchor = "bottom-center" if nodes.label_scale > 1.0 else "bottom-left"
        anchors = np.array([label_anchor(nodes, n) for n in names])
        texts = [nodes.labels[n].text for n in names]
        boxes = label_boxes(anchors, texts, pose, image_px, 0.75 * nodes.label_scale, anchor)
        keep = uncluttered(boxes, image_px, panel_px)
        hidden = frozenset(n for n, k in zip(names, keep) if not k and n != mine)
    nodes.hide_lesson_labels(hidden)
    return hidden
