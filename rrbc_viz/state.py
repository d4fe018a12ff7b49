"""What the app remembers besides the session: a small typed state every controller reads and writes under the app's
lock (`context.AppContext.lock`). The session (`rrbc_core.session.explorer.ExplorerSession`) holds the data and the
method; this holds how they are shown."""

from __future__ import annotations

from dataclasses import dataclass, field

from .camera import OPENING
from .node_values import LAYERS, Display

#: Layers shown when a source is loaded: all but labels, the heat map and the error slice.
DEFAULT_LAYERS = {name: name not in ("labels", "heatmap", "slice") for name in LAYERS}


@dataclass
class AppState:
    """The view's state.

    Attributes
    ----------
    selected : (kind, id) or None
        The selected point ("targets" or "fiducials"): it alone carries the drag gizmo.
    camera_preset : str
        The last camera preset shown (`camera.PRESETS`).
    presentation : bool
        Presentation mode (large text and markers, for a projector).
    display : Display
        Display-only options (arrow magnification, marker size, heat map and slice values).
    layers : dict
        Layer name (`nodes.LAYERS`) -> shown.
    lesson_index : int or None
        The lesson step shown (0-based), None outside the lesson.
    lesson_saved_layers : dict or None
        The layers before the lesson started (restored when it ends).
    messages : list of str
        Every message shown (status line, notifications), oldest first.
    heat_time, heat_cost : float
        When the heat map was last computed (monotonic s) and how long it took (s): drags refresh it live only when
        it is cheap, at most every `controllers.present.HEAT_INTERVAL_S`.
    heat_stale : bool
        The data changed since the heat map shown was computed.
    """

    selected: tuple[str, str] | None = None
    camera_preset: str = OPENING
    point_sort: str = "file order"  # how the point list is ordered (selection_card.SORTS)
    presentation: bool = False
    display: Display = field(default_factory=Display)
    layers: dict[str, bool] = field(default_factory=lambda: dict(DEFAULT_LAYERS))
    lesson_index: int | None = None
    lesson_saved_layers: dict[str, bool] | None = None
    messages: list[str] = field(default_factory=list)
    heat_time: float = 0.0
    heat_cost: float = 0.0
    heat_stale: bool = True
