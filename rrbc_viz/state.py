"""What the app shows besides the session: ONE typed state object, written only by the controllers under the app's
lock (`context.AppContext.lock`) and read by the presenting function (`picture.scene_picture`) and the controllers.
The session (`rrbc_core.session.explorer.ExplorerSession`) holds the data and the method; this holds how they are
shown and the results last shown. Views (the scene's nodes, the panels) hold only their handles and what they last
sent; no controller reads them back."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from .camera import OPENING
from .node_values import LAYERS, Display, LandingDisplay

if TYPE_CHECKING:
    import numpy as np

    from rrbc_core.analysis.diagnosis import Diagnosis
    from rrbc_core.analysis.scene_check import SceneCheck
    from rrbc_core.geometry.framing import CameraPose
    from rrbc_core.session.data_set import SessionData
    from rrbc_core.session.results import HeatMap, MonteCarloPlots, PlanningState
    from rrbc_core.session.slices import ErrorSlice
    from rrbc_core.session.tolerance_plan import TolerancePlan
    from rrbc_core.session.vec_view import VecView

#: Layers shown when a source is loaded: all but labels, the heat map and the error slice.
#: off at first: labels (they would crowd the first picture), the costlier fields, the bounds, and the arm's model
#: error at the tool (a magnified landing line and its figure, which the first picture does not explain)
DEFAULT_LAYERS = {name: name not in ("labels", "heatmap", "slice", "bounds", "arm_error") for name in LAYERS}


@dataclass
class AppState:
    """The view's state.

    Attributes
    ----------
    selected : (kind, id) or None
        The selected point ("targets" or "fiducials"): it alone carries the drag gizmo.
    camera_preset : str
        The last camera preset shown (`camera.PRESETS`).
    initial_camera : CameraPose or None
        The camera a newly opened tab starts with (as last set).
    point_sort : str
        How the point list is ordered (`selection_card.SORTS`).
    presentation : bool
        Presentation mode (large text and markers, for a projector).
    display : Display
        Display-only options (arrow magnification, marker size, heat map and slice values).
    layers : dict
        Layer name (`node_values.LAYERS`) -> shown.
    see_through : bool
        The work cell drawn see-through instead of solid.
    extent_mm : float
        The point sets' extent when the source was loaded, mm (the frames' axes and the registered frame's
        magnification are sized from it).
    drag_active : bool
        A drag is under way: the bullseye keeps its drawing scale (and the arm follows at most a few times a second)
        until it ends.
    drag_baseline : (ids, corrections (T, 3) robot frame mm) or None
        The targets' corrections when the last fiducial drag started: the targets whose correction it changed most
        are marked (`picture.ScenePicture.changed`); cleared by a target's drag and a new scene.
    target_arrows : bool
        The targets' correction arrows are drawn (a lesson step shows the fiducials' only).
    landing : LandingDisplay or None
        The landing bullseye last shown (its target, ring and points, robot frame mm).
    lesson_index : int or None
        The lesson step shown (0-based), None outside the lesson.
    lesson_saved_layers : dict or None
        The layers before the lesson started (restored when it ends).
    lesson_saved_zoom : float or None
        The regions' zoom before the lesson started (a step may draw them larger; restored when it ends).
    lesson_labels : tuple of str
        Kinds of point whose labels the lesson step shows.
    frames_zoom : float
        The sensor's frames' axes are drawn this many times their length (the lesson step that names them; 1
        otherwise).
    messages : list of str
        Every message shown (status line, notifications), oldest first.
    heat_map : HeatMap or None
        The heat map last shown (None until its layer is first on).
    heat_time, heat_cost : float
        When the heat map was last computed (monotonic s) and how long it took (s): drags refresh it live only when
        it is cheap, at most every `controllers.evaluate.HEAT_INTERVAL_S`.
    heat_stale : bool
        The data changed since the heat map shown was computed.
    error_slice : ErrorSlice or None
        The error slice last shown.
    plan : PlanningState or None
        The Plan tab's planning state last shown (predicted RMST, each target's coverage).
    plan_stale : bool
        A drag changed the fiducials since `plan` was computed.
    coverage_colours : bool
        Targets' regions (and halos) coloured by their coverage (the Plan tab's box).
    tolerance_plan : TolerancePlan or None
        The Plan tab's last plan to a tolerance (`rrbc plan --tolerance`'s result for the cell as it was), shown as
        ghosts until used, cleared or another source is loaded.
    vec_on, vec_target, vec_view
        VEC compared (the box ticked and the source has an arm); the target whose tool the Arm tab shows; the VecView
        last shown (None: off, no arm, or refused).
    vec_tool_asked
        (target, tilt, azimuth) the user last chose on the tool sliders (None: none since a refusal, another target
        or another cell). While set, the server sends the sliders no value: any it sent (even the user's own from a
        moment ago) could set a slider back under keys still pressed.
    mc_trials, mc_plots, mc_draw, mc_seed
        The trials a Monte Carlo run takes (the tab's slider); the Monte Carlo plots last shown; Run-again presses so
        far; the noise seed of the last run requested (None: the session's).
    diagnosis, diagnosis_data, diagnosis_stale
        The Diagnose tab's last verdict (None: none or an error), the data set it came from, and whether the data
        changed since.
    click_mode, target_region_mm
        What a click on the cell adds (None: clicks select) and an added target's region (cube edge, mm).
    model_check, model_check_file, model_check_scene_text
        The Model tab's last check of the scene's model (None: none or refused), the offered file it was held
        against, and the open scene's text when it is an extension the tab loaded (None: the scene's own file).
    """

    selected: tuple[str, str] | None = None
    camera_preset: str = OPENING
    initial_camera: CameraPose | None = None
    point_sort: str = "file order"
    presentation: bool = False
    display: Display = field(default_factory=Display)
    layers: dict[str, bool] = field(default_factory=lambda: dict(DEFAULT_LAYERS))
    see_through: bool = False
    extent_mm: float = 1000.0
    drag_active: bool = False
    drag_baseline: tuple[tuple, np.ndarray] | None = None
    target_arrows: bool = True
    landing: LandingDisplay | None = None
    lesson_index: int | None = None
    lesson_saved_layers: dict[str, bool] | None = None
    lesson_saved_zoom: float | None = None
    lesson_labels: tuple[str, ...] = ()
    frames_zoom: float = 1.0
    messages: list[str] = field(default_factory=list)
    heat_map: HeatMap | None = None
    heat_time: float = 0.0
    heat_cost: float = 0.0
    heat_stale: bool = True
    error_slice: ErrorSlice | None = None
    plan: PlanningState | None = None
    plan_stale: bool = False
    coverage_colours: bool = False
    tolerance_plan: TolerancePlan | None = None
    vec_on: bool = False
    vec_target: str = ""
    vec_view: VecView | None = None
    vec_tool_asked: tuple[str, float, float] | None = None
    mc_trials: int = 200
    mc_plots: MonteCarloPlots | None = None
    mc_draw: int = 0
    mc_seed: int | None = None
    diagnosis: Diagnosis | None = None
    diagnosis_data: SessionData | None = None
    diagnosis_stale: bool = False
    click_mode: str | None = None
    target_region_mm: float = 4.0
    model_check: SceneCheck | None = None
    model_check_file: str = ""
    model_check_scene_text: str | None = None

    def vec_landings(self) -> dict[str, np.ndarray]:
        """Target id -> VEC's landing (3,), robot frame mm, while VEC is compared (else empty)."""
        v = self.vec_view
        return {} if v is None else {pid: v.robot_vec[i] for i, pid in enumerate(v.ids)}
