"""The scene's text labels of points and frames: made, sized, shown and decluttered behind verbs.

Every label is a viser label node named by where it hangs (`/<kind>/<id>/gizmo/label` under a point's drag handle,
`/registration/labels/<id>`); `SceneNodes` makes them through `add` and asks for what it shows. Which labels show:
all of them when the labels layer is on (not in presentation mode, whose large labels would overlap), the selected
point's always, and a lesson step's kinds less those that would overlap another or run under the panel
(`lesson_labels.declutter`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Literal

import numpy as np
import viser

from rrbc_core.geometry.framing import camera_basis
from rrbc_core.geometry.label_layout import label_boxes

from . import lesson_labels

#: (handle, attribute, value): set unless it is what was last set there (`SceneNodes._assign`)
Assign = Callable[[Any, str, Any], None]


class PointLabels:
    """The labels of one build; `scale` > 1 is presentation mode (larger, centred over their point)."""

    def __init__(self, scene: viser.SceneApi, assign: Assign) -> None:
        self._scene = scene
        self._assign = assign
        self._handles: dict[str, viser.LabelHandle] = {}  # node name of the label -> handle
        self._scale = 1.0  # labels' screen size factor (presentation mode)
        self._reanchored: str | None = None  # the label drawn with its own anchor to stay in view (a lesson's)
        self._lesson_kinds: tuple[str, ...] = ()  # kinds of point whose labels a lesson step shows
        self._lesson_named: tuple[str, ...] = ()  # of those, the labels of the points its text names (placed first)
        self._lesson_hidden: frozenset[str] = frozenset()  # ... less those that would overlap
        self._raised: str | None = None  # the selected point's label, drawn above its drag handle
        self._sided: dict[str, str] = {}  # lesson labels drawn with another anchor (their own would meet a label)
        self._heights = (0.0, 0.0)  # point labels' heights above their point (mm): the others', the raised one's
        self._side_mm = 0.0  # how far beside the line through its point the raised label starts (mm)

    @property
    def scale(self) -> float:
        return self._scale

    @property
    def compact(self) -> bool:
        """Presentation mode: short texts, large labels."""
        return self._scale > 1.0

    def _anchor(self) -> Literal["bottom-center", "bottom-left"]:
        # large labels centred over their point (short texts): they stay in the view's free part
        return "bottom-center" if self.compact else "bottom-left"

    def names(self) -> list[str]:
        """The names of every label, in the order they were made."""
        return list(self._handles)

    def position(self, name: str) -> np.ndarray:
        """Label `name`'s position relative to its parent node (mm)."""
        return np.asarray(self._handles[name].position, float)

    def box(self, name: str, where: np.ndarray, pose, image_px) -> np.ndarray:
        """Label `name`'s screen box [left, top, right, bottom] (CSS px) as drawn at `where` (robot frame, mm) with
        its anchor, seen by `pose` in an image of `image_px`; NaN behind the camera."""
        h = self._handles[name]
        return label_boxes(np.reshape(where, (1, 3)), [str(h.text)], pose, image_px, 0.75 * self._scale, h.anchor)[0]

    def clear(self) -> None:
        self._handles.clear()
        self._raised = None
        self._sided = {}

    def add(self, name: str, text: str, position, visible: bool) -> None:
        """A new label `name` reading `text` at `position` (its parent's frame, mm)."""
        self._handles[name] = self._scene.add_label(
            name,
            text,
            position=np.asarray(position, float),
            font_size_mode="screen",
            font_screen_scale=0.75 * self._scale,
            anchor="bottom-left",  # as before presentation mode re-anchors them (`set_scale`)
            visible=visible,
        )

    def set_text(self, name: str, text: str) -> None:
        self._assign(self._handles[name], "text", text)

    def move(self, name: str, position) -> None:
        self._handles[name].position = np.asarray(position, float)

    def lift_point_labels(self, height_mm: float, raised_mm: float) -> None:
        """Every point label (under a drag handle) drawn `height_mm` above its point, the selected one's (`raise_label`)
        `raised_mm`."""
        self._heights = (float(height_mm), float(raised_mm))
        for name, h in self._handles.items():
            if name.endswith("/gizmo/label"):
                h.position = np.array([0.0, 0.0, self._heights[name == self._raised]])

    def raise_label(self, mine: str | None, height_mm: float, raised_mm: float, side_mm: float = 0.0) -> None:
        """The selected point's label `mine` (None: none) drawn `raised_mm` above its point, over its drag handle's up
        arrow, whose arrows and planes would cover it at the usual `height_mm` (issue 39); the one raised before
        back down. Seen by a camera (`declutter`), it starts `side_mm` beside the vertical line through its point."""
        self._heights = (float(height_mm), float(raised_mm))
        self._side_mm = float(side_mm)
        if mine == self._raised:
            return
        if self._raised in self._handles:
            self._handles[self._raised].position = np.array([0.0, 0.0, self._heights[0]])
        if mine in self._handles:
            self._handles[mine].position = np.array([0.0, 0.0, self._heights[1]])
        self._raised = mine

    def set_scale(self, factor: float) -> None:
        """Labels' screen size × factor (presentation mode when > 1)."""
        self._scale = float(factor)
        for h in self._handles.values():
            h.font_screen_scale = 0.75 * self._scale
            h.anchor = self._anchor()

    def set_lesson(self, kinds: tuple[str, ...], named: tuple[str, ...] = ()) -> None:
        """Show the labels of these kinds of point (a lesson step's) besides the others (after `show`); `named`: the
        labels of the points its text names, kept before the others when labels would overlap."""
        self._lesson_kinds = tuple(kinds)
        self._lesson_named = tuple(named)
        self._lesson_hidden = frozenset()
        self._unside(keep=self._reanchored)  # drawn on another side for the step before: back to the common anchor

    def lesson_shows(self, kind: str) -> bool:
        """Whether the lesson step shows the labels of this kind of point (`set_lesson`)."""
        return kind in self._lesson_kinds

    def _unside(self, keep: str | None) -> None:
        """Put the labels drawn on another side back to the common anchor, all but `keep`'s."""
        for name in self._sided:
            if name in self._handles and name != keep:
                self._handles[name].anchor = self._anchor()
        self._sided = {}

    def declutter(
        self, mine: str | None, anchor_of: Callable[[str], np.ndarray], pose, image_px, panel_px: float
    ) -> frozenset[str]:
        """Hide the lesson step's labels that would overlap another or run under the panel when seen by `pose` (a
        `CameraPose`) in an image of `image_px` (width, height) CSS px, the selected point's label `mine` first and
        kept inside the view; `anchor_of(name)` is where a label is drawn (robot frame, mm). Returns the names
        hidden (shown after `show`)."""
        lesson = tuple(f"/{k}/" for k in self._lesson_kinds)
        names = [n for n in self._handles if n.startswith(lesson)]
        named = [n for n in self._lesson_named if n in names]
        names = named + [n for n in names if n not in named]  # what the text names is placed first
        anchor: Any = self._anchor()
        scale = 0.75 * self._scale
        first_anchor: Any = None
        moved, self._reanchored = self._reanchored, None
        if moved in self._handles and moved != mine:  # an earlier selection's label back to the common anchor
            self._handles[moved].anchor = anchor
        self._unside(keep=mine)  # and an earlier step's labels drawn on another side
        if mine is not None and mine in self._handles:  # the selected point's label kept inside the view
            first_anchor = self._beside_its_point(mine, anchor_of, pose, image_px, panel_px)
            self._reanchored = mine
        labels = {n: (anchor_of(n), str(self._handles[n].text)) for n in names}
        self._lesson_hidden, self._sided = lesson_labels.declutter(
            labels, mine, pose, image_px, panel_px, scale, anchor, first_anchor
        )
        for name, side in self._sided.items():
            self._handles[name].anchor = side  # type: ignore[assignment]
        return self._lesson_hidden

    def _beside_its_point(self, mine: str, anchor_of: Callable[[str], np.ndarray], pose, image_px, panel_px) -> str:
        """The selected point's label `mine` drawn inside the view's free part (`lesson_labels.inside_anchor`) and
        starting beside the vertical line through its point, not on it: its drag handle's up arrow and, at a target,
        the arm's stylus come down that line (issue 39: they crossed the label's first characters). Its text runs
        left or right from `side_mm` beside the line (a centred label, presentation mode's, is drawn from its side
        too). Returns its anchor."""
        h = self._handles[mine]
        raised = np.array([0.0, 0.0, self._heights[1]]) if mine == self._raised else np.asarray(h.position, float)
        h.position = raised
        own = self._anchor()
        own = "bottom-left" if own.endswith("center") and self._side_mm > 0 else own
        scale = 0.75 * self._scale
        first = lesson_labels.inside_anchor(anchor_of(mine), str(h.text), pose, image_px, panel_px, scale, own)
        if self._side_mm > 0 and not first.endswith("center"):
            right = camera_basis(pose.forward, pose.up)[1]
            h.position = raised + (1.0 if first.endswith("left") else -1.0) * self._side_mm * right
        h.anchor = first  # type: ignore[assignment]
        return first

    def show(self, layer_on: bool, mine: str | None, also: frozenset[str] = frozenset()) -> None:
        """Make visible what should show (module docstring): `layer_on` the labels layer, `mine` the selected
        point's label name (None without a selection), `also` labels shown whatever the layer (the targets a
        fiducial's drag changed most)."""
        on = layer_on and not self.compact
        lesson = tuple(f"/{k}/" for k in self._lesson_kinds)
        hidden = self._lesson_hidden
        for name, h in self._handles.items():
            shown = on or name == mine or name in also or (name.startswith(lesson) and name not in hidden)
            self._assign(h, "visible", shown)
