"""A lesson step's point labels without overlaps: those that would meet another label or run under the panel in
a tab's view are hidden (the named point's first). The layout is the core's (`rrbc_core.geometry.label_layout`);
the scene's nodes hand in their labels' texts and where they are drawn (`nodes.SceneNodes.declutter_lesson_labels`)."""

from __future__ import annotations

import numpy as np

from rrbc_core.geometry.label_layout import label_boxes, overlap, placed

#: Where a lesson label may go besides its own anchor when that would meet another label or leave the view's free
#: part: below its point, then to one side (the first that fits; `label_layout.placed`). A centred label (presentation
#: mode's) over a point near the view's left edge or the panel runs right or left from it instead.
OTHER_ANCHORS = {
    "bottom-left": ("top-left", "bottom-right", "top-right"),
    "bottom-center": ("top-center", "bottom-left", "bottom-right", "top-left", "top-right"),
}


def declutter(
    labels: dict[str, tuple[np.ndarray, str]],
    first: str | None,
    pose,
    image_px,
    panel_px: float,
    font_scale: float,
    anchor: str,
    first_anchor: str | None = None,
) -> tuple[frozenset[str], dict[str, str]]:
    """The names of `labels` (name -> (where it is drawn (3,) robot frame mm, its text)) to hide so that none
    overlaps another or runs under the panel when seen by `pose` (a `CameraPose`) in an image of `image_px` (width,
    height) CSS px, and the labels to draw with another anchor than `anchor` (name -> anchor: `OTHER_ANCHORS`, where
    their own would meet another): `first` (the selected point's label, drawn with `first_anchor` if given) is
    placed first and never hidden, the others in order."""
    names = list(labels)
    if first in names:
        names.remove(first)
        names.insert(0, first)
    if not names:
        return frozenset(), {}
    anchors = np.array([labels[n][0] for n in names])
    texts = [labels[n][1] for n in names]
    options = (anchor, *OTHER_ANCHORS.get(anchor, ()))
    cand = np.stack([label_boxes(anchors, texts, pose, image_px, font_scale, a) for a in options], axis=1)
    if names[0] == first:  # the selected label: its own anchor only
        cand[0, 1:] = np.nan
        if first_anchor is not None:
            cand[0, 0] = label_boxes(anchors[:1], texts[:1], pose, image_px, font_scale, first_anchor)[0]
    choice = placed(cand, image_px, panel_px)
    hidden = frozenset(n for n, k in zip(names, choice) if k < 0 and n != first)
    return hidden, {n: options[k] for n, k in zip(names, choice) if k > 0}


def inside_anchor(point, text: str, pose, image_px, panel_px: float, font_scale: float, anchor: str) -> str:
    """The anchor that keeps a label (`text` drawn at `point` (3,) robot frame mm) inside the view's free part
    (left of the panel) when seen by `pose`: `anchor` when its box fits, else "bottom-left" (the text runs right
    from a point near the left edge) or "bottom-right" (left from a point near the panel)."""
    box = label_boxes(np.reshape(point, (1, 3)), [text], pose, image_px, font_scale, anchor)[0]
    if not np.all(np.isfinite(box)):
        return anchor
    if box[0] < 0:
        return "bottom-left"
    if box[2] > float(image_px[0]) - panel_px:
        return "bottom-right"
    return anchor


def side_anchor(point, text: str, avoid, pose, image_px, panel_px: float, font_scale: float, own: str) -> str | None:
    """The anchor of a label (`text` drawn at `point` (3,) robot frame mm) whose box, seen by `pose` in an image of
    `image_px`, lies left of the panel and clear of the boxes `avoid` ((K, 4) [left, top, right, bottom] CSS px; NaN
    rows ignored): `own` when it does, else the first of top-left, bottom-right, top-right, bottom-left that does;
    None when none does (the label is better hidden)."""
    boxes = np.asarray(avoid, float).reshape(-1, 4)
    for anchor in dict.fromkeys((own, "top-left", "bottom-right", "top-right", "bottom-left")):
        box = label_boxes(np.reshape(point, (1, 3)), [text], pose, image_px, font_scale, anchor)[0]
        inside = bool(np.all(np.isfinite(box)) and box[0] >= 0 and box[2] <= float(image_px[0]) - panel_px)
        if inside and not any(overlap(box, b) for b in boxes):
            return anchor
    return None
