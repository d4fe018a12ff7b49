"""Which point labels to show so that none overlaps another or runs under the panel (the lessons' labels).

A label is drawn at a fixed size on screen (viser's "screen" labels: an em of `LABEL_EM_PX` CSS px times its font
scale) beside its anchor point, which the camera projects as in `framing.project`. Its box is estimated from its
text: `CHAR_EM` em per character and `LINE_EM` em tall. Labels are taken greedily in the order given (the one a
lesson's text names first): a label is kept when its anchor is in front of the camera, its box lies in the image
left of the panel, and it does not meet a box already kept (with `GAP_PX` between them); a label that may be drawn
with other anchors (`placed`) takes the first of them that fits.

Frames and units: anchors (N, 3) robot frame, mm; image and boxes in CSS px, origin at the image's top left.
"""

from __future__ import annotations

import numpy as np

from rrbc_core.geometry.framing import CameraPose, project

#: viser's screen labels: 12 CSS px per em at font scale 1.
LABEL_EM_PX = 12.0
#: Estimated advance per character (em) and line height (em) of the labels' sans-serif font.
CHAR_EM = 0.6
LINE_EM = 1.25
#: Free pixels kept between two labels.
GAP_PX = 2.0


def label_boxes(anchors, texts, pose: CameraPose, image_px, font_scale: float, anchor: str = "bottom-left"):
    """Screen boxes (N, 4) [left, top, right, bottom] (CSS px) of labels `texts` (N,) at `anchors` (N, 3) seen by
    `pose` in an image of `image_px` (width, height); rows of labels behind the camera are NaN. `anchor`:
    "bottom-left" (the text starts at the point), "bottom-center" (centred over it) or "bottom-right" (it ends
    there), above the point; "top-left", "top-center" or "top-right" the same below it."""
    a = np.asarray(anchors, float).reshape(-1, 3)
    w_img, h_img = (float(v) for v in image_px)
    ndc, depth = project(a, pose)
    x = (ndc[:, 0] + 1.0) / 2.0 * w_img
    y = (1.0 - ndc[:, 1]) / 2.0 * h_img
    em = LABEL_EM_PX * float(font_scale)
    width = np.array([CHAR_EM * em * max(len(str(t)), 1) for t in texts], float)
    height = LINE_EM * em
    side = anchor.split("-")[-1]
    left = {"center": x - width / 2.0, "right": x - width}.get(side, x)
    top = y if anchor.startswith("top") else y - height
    boxes = np.stack([left, top, left + width, top + height], axis=1)
    boxes[~(depth > 0)] = np.nan
    return boxes


def sphere_boxes(centres, radii, pose: CameraPose, image_px) -> np.ndarray:
    """Screen boxes (N, 4) [left, top, right, bottom] (CSS px) around spheres at `centres` (N, 3) robot frame, mm,
    of `radii` (N,) mm, seen by `pose` in an image of `image_px` (width, height): the square that holds each one's
    disc; NaN rows behind the camera."""
    c = np.asarray(centres, float).reshape(-1, 3)
    h_img = float(image_px[1])
    ndc, depth = project(c, pose)
    x = (ndc[:, 0] + 1.0) / 2.0 * float(image_px[0])
    y = (1.0 - ndc[:, 1]) / 2.0 * h_img
    with np.errstate(divide="ignore", invalid="ignore"):
        r_px = np.asarray(radii, float) * (h_img / 2.0) / (np.tan(pose.fov_y / 2.0) * depth)
    boxes = np.stack([x - r_px, y - r_px, x + r_px, y + r_px], axis=1)
    boxes[~(depth > 0)] = np.nan
    return boxes


def overlap(a, b, gap_px: float = GAP_PX) -> bool:
    """Whether two boxes [left, top, right, bottom] (CSS px) come closer than `gap_px` (False when one is NaN)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        return False
    return not (a[2] + gap_px <= b[0] or b[2] + gap_px <= a[0] or a[3] + gap_px <= b[1] or b[3] + gap_px <= a[1])


def uncluttered(boxes, image_px, panel_px: float = 0.0, gap_px: float = GAP_PX) -> np.ndarray:
    """(N,) bool: the labels to show, taken in the rows' order (module docstring), from their `boxes` (N, 4) as
    `label_boxes` gives them; `panel_px`: the width the panel covers at the image's right."""
    b = np.asarray(boxes, float).reshape(-1, 1, 4)
    return placed(b, image_px, panel_px, gap_px) == 0


def placed(candidates, image_px, panel_px: float = 0.0, gap_px: float = GAP_PX) -> np.ndarray:
    """(N,) int: for each label, taken in the rows' order, the first of its candidate boxes (N, A, 4) (one per
    anchor it may be drawn with, as `label_boxes` gives them; NaN rows: not a candidate) that lies in the image left
    of the panel (`panel_px` wide at the right) and meets no box already placed; -1 where none does (hidden)."""
    c = np.asarray(candidates, float).reshape(len(candidates), -1, 4)
    w_img, h_img = (float(v) for v in image_px)
    choice = np.full(len(c), -1, int)
    kept: list[np.ndarray] = []
    for i, boxes in enumerate(c):
        for a, box in enumerate(boxes):
            if not np.all(np.isfinite(box)):
                continue
            if box[0] < 0 or box[1] < 0 or box[2] > w_img - panel_px or box[3] > h_img:
                continue
            if any(overlap(box, k, gap_px) for k in kept):
                continue
            choice[i] = a
            kept.append(box)
            break
    return choice
