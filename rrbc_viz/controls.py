"""The control panel (shared by every browser tab): one panel class per tab, each owning its widgets.

`ExplorePanel` (results, method, errors), `ViewPanel` (display, layers, heat map), `LearnPanel` (the lesson),
`MonteCarloPanel`, `FilePanel`, the Plan tab (`planning_panel.PlanningPanel`), and the plug-in tabs the app hands in
(`tab_plugin.TabSpec`: Diagnose, Model, …; their panels in `Controls.tabs`).
`Controls` lays the tabs out and holds the status line. A panel only forwards user input to the app (through
`actions.Actions`) and shows what the app hands back; it holds no RRBC state of its own. Programmatic updates
(`sync_*`) run under the shared `Syncing` flag so that the value callbacks they re-enter (viser runs `on_update`
when Python assigns `.value`) do nothing.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import viser

from rrbc_core import interpolation, registration
from rrbc_core.methods import method_flags
from rrbc_core.session.evaluation import Settings

from .authoring_panel import AuthoringPanel
from .camera import PANEL_WIDTH_PX, PRESENTATION_PANEL_WIDTH_PX, PRESETS
from .checks_panel import ChecksPanel
from .colors import legend_html
from .file_panel import FilePanel
from .node_values import LAYER_LABELS, LAYERS, Display
from .picture import BOUND_SCALES, CHECK_ERROR_CHOICES
from .planning_panel import PlanningPanel
from .selection_panel import Bullseye, SelectionPanel
from .slice_nodes import SLICE_AXES, SLICE_CHOICES
from .syncing import Syncing, clamped
from .vec_panel import VecPanel

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from .actions import Actions
    from .stage import Stage

    #: a plug-in tab's panel as the control panel builds it: (name, label, icon (a `viser.Icon` name), the panel's
    #: class or factory, called with the gui and a function returning the tab's controller); `tab_plugin.TabSpec`
    TabPanel = tuple[str, str, str, Callable[[Any, Callable[[], Any]], Any]]

HEAT_CHOICES = {
    "scene": (("RRBC error", "rrbc"), ("rigid error", "rigid")),
    "measurements": (("correction size", "correction"), ("correction std (gp)", "std")),
}
MAG_MAX = 2000
#: Presentation mode's style sheet: larger text for a projector (the panel's sizes are rem-based).
#: The panel's (outermost) scroll area never taller than the window (viser 1.1.1 sizes it from the panel's content
#: and its own font size), so every control can be scrolled to at any window height.
PANEL_CSS = (
    ".mantine-Paper-root .mantine-ScrollArea-root:not(.mantine-ScrollArea-root .mantine-ScrollArea-root), "
    ".mantine-Paper-root .mantine-ScrollArea-viewport:not(.mantine-ScrollArea-root .mantine-ScrollArea-viewport) "
    "{ max-height: calc(100vh - 3.5rem) !important; }"
    # the plots' legends (uPlot) at the panel's body size, not 0.65 of it
    ".mantine-Paper-root .u-legend th, .mantine-Paper-root .u-legend td { font-size: 0.875rem !important; }"
)
#: Presentation mode (a projector at 1280x720): the panel's sizes are in rem, so a root font of 27.5 px makes its
#: body text (0.875 rem) 24 px.
PRESENTATION_FONT_PX = 27.5
PRESENTATION_CSS = (
    f"<style>html {{ font-size: {PRESENTATION_FONT_PX}px !important; }} {PANEL_CSS} "
    # button groups (the camera presets) and the tabs' names at the body size too
    ".mantine-Paper-root .mantine-Button-root, .mantine-Paper-root .mantine-Tabs-tab "
    "{ font-size: 0.875rem !important; } "
    # the panel's bullseye (an SVG with a viewBox) as wide as the panel: its ring scale and axes grow with it
    ".mantine-Paper-root svg[data-ring-mm] { width: 100%; height: auto; } "
    # the tabs on one row: every tab an icon, the open one also named (the others' names stay readable by a screen
    # reader and by the page's text), so a lesson's text starts in the window's upper half
    # (viser 1.1.1's tab bar: role tablist, tabs role tab with aria-selected, an icon div then a label span; a tab's
    # title attribute names it on hover)
    ".mantine-Paper-root [role=tablist] { flex-wrap: nowrap !important; overflow-x: auto; } "
    ".mantine-Paper-root [role=tab] { padding: 0 0.45em !important; flex-shrink: 0; } "
    ".mantine-Paper-root [role=tab][aria-selected=false] > span "
    "{ position: absolute; width: 1px; height: 1px; overflow: hidden; clip-path: inset(50%); white-space: nowrap; } "
    ".mantine-Paper-root [role=tab][aria-selected=false] > div { margin-right: 0 !important; } "
    # the headline on one line, its note small
    ".rrbc-headline-main { font-size: 1rem !important; } .rrbc-headline-note { font-size: 0.7rem !important; margin-bottom: 0.35rem; }</style>"
)
NORMAL_CSS = f"<style>{PANEL_CSS}</style>"


def _band(label: str, color: str) -> dict:
    """A thin dashed line: one edge of an interval."""
    return {"label": label, "stroke": color, "width": 1, "dash": [4, 4]}


def _series(label: str, color: str, points: bool = False) -> dict:
    s: dict = {"label": label, "stroke": color, "width": 2}
    if points:
        s["width"] = 1
        s["points"] = {"show": True, "size": 5, "fill": color}
    return s


def _forward(handle, syncing: Syncing, send, name: str, cast):
    """A value callback that hands the widget's new value to the app as ``send(client=..., name=cast(value))`` (a
    setting or a display option), unless the value was assigned by a `sync` (`syncing.on`)."""

    def on_update(event: viser.GuiEvent) -> None:
        if not syncing.on:
            value = cast(clamped(handle)) if hasattr(handle, "min") else cast(handle.value)
            send(client=event.client, **{name: value})

    return on_update


class ExplorePanel:
    """Explore tab: the source, the results (scale line, summary, per-target table), the method and error sizes."""

    def __init__(self, gui, app: Actions, syncing: Syncing):
        self.app, self.syncing = app, syncing
        self.source = gui.add_markdown("")
        with gui.add_folder("Results"):
            self.magnification = gui.add_slider(
                "Arrow magnification",
                1,
                MAG_MAX,
                1,
                200,
                hint="Correction arrows and landing offsets are drawn this many times longer than they are",
            )
            self.bound_scale = gui.add_dropdown(
                "95 % bounds drawn",
                tuple(BOUND_SCALES.values()),
                initial_value=BOUND_SCALES["arrows"],
                hint="The bounds layer's ellipsoids: magnified as the arrows and landing offsets are (comparable with "
                "them), or at true size (tenths of a mm: hidden inside the markers unless zoomed in)",
            )
            self.check_error = gui.add_dropdown(
                "Check errors drawn",
                tuple(CHECK_ERROR_CHOICES.values()),
                initial_value=CHECK_ERROR_CHOICES["rrbc"],
                hint="A measurement file's check rows: the error of the position RRBC or the rigid transform "
                "sends the robot to (× the arrow magnification, coloured by size; the largest labelled)",
            )
            self.scale = gui.add_markdown("")
            self.summary = gui.add_markdown("")
            self.table = gui.add_markdown("")
        with gui.add_folder("Method"):
            self.registration = gui.add_dropdown(
                "Registration", tuple(registration.STRATEGIES), initial_value="least-squares"
            )
            self.interpolation = gui.add_dropdown("Interpolation", tuple(interpolation.METHODS), initial_value="idw")
            # one widget per method option the app offers, from the option fields' specs (bounds stated once)
            self.options: dict = {}  # flag -> widget
            self.option_owners: dict = {}  # flag -> names of the methods that take it
            for flag, owners in method_flags().items():
                spec = owners[0][2]
                if flag == "seed" or not (spec.choices or spec.ui):
                    continue
                if spec.choices:
                    widget = gui.add_dropdown(spec.label, spec.choices, initial_value=spec.default, hint=spec.help)
                else:
                    assert spec.ui is not None
                    lo, hi, step = spec.ui
                    widget = gui.add_slider(spec.label, lo, hi, step, spec.default, hint=spec.help)
                self.options[flag] = widget
                self.option_owners[flag] = {name for _, name, _ in owners}
        with gui.add_folder("Errors (scene)"):
            self.noise = gui.add_slider(
                "Noise size ×", 0.0, 3.0, 0.05, 1.0, hint="Multiplies the scene's random error terms"
            )
            self.bias = gui.add_slider(
                "Bias size ×", 0.0, 3.0, 0.05, 1.0, hint="Multiplies the scene's systematic error terms"
            )
            self.seed_md = gui.add_markdown("")
            self.new_seed = gui.add_button("New random seed", icon=viser.Icon.DICE)
        gui.add_markdown(
            "Click a target or fiducial (or pick it under *Selected point*) to select it; drag the arrows of its "
            "handle to move it. Robot frame, mm."
        )
        for handle, name, cast in (
            (self.registration, "registration", str),
            (self.interpolation, "interpolation", str),
            (self.noise, "noise_scale", float),
            (self.bias, "bias_scale", float),
            *(
                (widget, flag.replace("-", "_"), method_flags()[flag][0][2].kind)
                for flag, widget in self.options.items()
            ),
        ):
            handle.on_update(_forward(handle, syncing, lambda **kw: app.evaluate.change_settings(**kw), name, cast))
        self.magnification.on_update(
            _forward(self.magnification, syncing, lambda **kw: app.evaluate.set_display(**kw), "magnification", float)
        )
        by_label = {label: value for value, label in BOUND_SCALES.items()}
        self.bound_scale.on_update(
            _forward(self.bound_scale, syncing, lambda **kw: app.evaluate.set_display(**kw), "bound_scale",
                     lambda label: by_label.get(label, label))
        )  # fmt: skip
        by_check = {label: value for value, label in CHECK_ERROR_CHOICES.items()}
        self.check_error.on_update(
            _forward(self.check_error, syncing, lambda **kw: app.evaluate.set_display(**kw), "check_error",
                     lambda label: by_check.get(label, label))
        )  # fmt: skip
        self.new_seed.on_click(lambda event: app.evaluate.new_seed(client=event.client))

    def sync(self, settings: Settings | None, kind: str, display: Display | None = None) -> None:
        with self.syncing.quiet():
            if display is not None:
                self.magnification.value = float(min(max(display.magnification, 1), MAG_MAX))
                self.bound_scale.value = BOUND_SCALES[display.bound_scale]
                self.check_error.value = CHECK_ERROR_CHOICES[display.check_error]
                return
            assert settings is not None
            self.registration.value = settings.registration
            self.interpolation.value = settings.interpolation
            chosen = {settings.registration, settings.interpolation}
            for flag, widget in self.options.items():
                widget.value = getattr(settings, flag.replace("-", "_"))
                widget.visible = bool(self.option_owners[flag] & chosen)
            self.noise.value = float(settings.noise_scale)
            self.bias.value = float(settings.bias_scale)
            scene = kind == "scene"
            self.noise.visible = self.bias.visible = self.new_seed.visible = scene  # measured data: nothing to scale
            self.seed_md.content = (
                f"Noise seed **{settings.seed}**."
                if scene
                else f"Measured data: noise and bias are what they are (seed {settings.seed} only "
                "seeds annealing and clustering)."
            )

    def show_source(self, markdown: str) -> None:
        """What is open: the source's name and kind."""
        self.source.content = markdown

    def show_results(self, scale: str, summary: str, table: str) -> None:
        """The arrows' scale line, the summary and the per-target table (`tables`)."""
        for widget, text in ((self.scale, scale), (self.summary, summary), (self.table, table)):
            if widget.content != text:
                widget.content = text

    @property
    def neighbors(self):
        return self.options["neighbors"]

    @property
    def power(self):
        return self.options["power"]

    @property
    def smoothing(self):
        return self.options["smoothing"]


class ViewPanel:
    """View tab: camera presets, marker size, region zoom, layers, the heat map's value and legend."""

    def __init__(self, gui, app: Actions, syncing: Syncing):
        self.app, self.syncing = app, syncing
        self.camera = gui.add_button_group("Camera", PRESETS)
        self.camera.on_click(lambda event: app.views.show_camera(self.camera.value, client=event.client))
        self.presentation = gui.add_checkbox(
            "Presentation mode", False, hint="Large text, a collapsible panel, larger markers: for a projector"
        )
        self.presentation.on_update(
            lambda event: None if self.syncing.on else app.views.set_presentation(self.presentation.value)
        )
        self.see_through = gui.add_checkbox("See-through cell", False, hint="Show what lies under the cell's surfaces")
        self.see_through.on_update(
            lambda event: None if self.syncing.on else app.views.set_see_through(self.see_through.value)
        )
        self.marker = gui.add_slider("Marker radius (mm)", 0.5, 50.0, 0.5, 8.0)
        self.region_zoom = gui.add_slider(
            "Region zoom ×",
            1.0,
            50.0,
            0.5,
            1.0,
            hint="Regions of variability and heat-map samples drawn this many times larger about their target",
        )
        with gui.add_folder("Layers"):
            self.layers = {name: gui.add_checkbox(LAYER_LABELS[name], True) for name in LAYERS}
        with gui.add_folder("Heat map"):
            self.heat_value = gui.add_dropdown("Colour by", tuple(k for k, _ in HEAT_CHOICES["scene"]))
            self.legend = gui.add_markdown(
                "Turn on the heat-map layer to see predicted error over the targets' regions of variability."
            )
        with gui.add_folder("Error slice"):
            self.slice_value = gui.add_dropdown("Slice shows", tuple(k for k, _ in SLICE_CHOICES))
            self.slice_axis = gui.add_dropdown("Plane", tuple(k for k, _ in SLICE_AXES))
            self.slice_offset = gui.add_slider("Plane at (mm)", -1000.0, 1000.0, 1.0, 0.0)
            self.slice_legend = gui.add_markdown("Turn on the error-slice layer to see predicted error on a plane.")

        @self.slice_value.on_update
        def _(event: viser.GuiEvent) -> None:
            if not self.syncing.on:
                app.evaluate.set_display(client=event.client, slice_value=dict(SLICE_CHOICES)[self.slice_value.value])

        @self.slice_axis.on_update
        def _(event: viser.GuiEvent) -> None:
            if not self.syncing.on:
                app.evaluate.set_display(
                    client=event.client, slice_axis=dict(SLICE_AXES)[self.slice_axis.value], slice_offset=None
                )

        self.slice_offset.on_update(
            _forward(self.slice_offset, syncing, lambda **kw: app.evaluate.set_display(**kw), "slice_offset", float)
        )
        for handle, name, cast in (
            (self.marker, "marker_mm", float),
            (self.region_zoom, "region_zoom", float),
        ):
            handle.on_update(_forward(handle, syncing, lambda **kw: app.evaluate.set_display(**kw), name, cast))

        @self.heat_value.on_update
        def _(event: viser.GuiEvent) -> None:
            if not self.syncing.on:
                choices = dict(HEAT_CHOICES[app.session.kind])
                app.evaluate.set_display(client=event.client, heat_value=choices.get(self.heat_value.value, "rrbc"))

        for name, box in self.layers.items():

            def on_layer(event: viser.GuiEvent, name=name, box=box) -> None:
                if not self.syncing.on:
                    app.evaluate.set_layer(name, bool(box.value))

            box.on_update(on_layer)

    def sync(self, display: Display, kind: str) -> None:
        with self.syncing.quiet():
            self.marker.value = float(display.marker_mm)
            self.region_zoom.value = float(display.region_zoom)
            labels = HEAT_CHOICES[kind]
            self.heat_value.options = tuple(k for k, _ in labels)
            self.heat_value.value = next((k for k, v in labels if v == display.heat_value), labels[0][0])

    def show_heat_legend(self, markdown: str) -> None:
        self.legend.content = markdown

    def show_slice_legend(self, markdown: str) -> None:
        self.slice_legend.content = markdown

    def show_applicable_layers(self, names) -> None:
        """Only the layers that have something to show get a checkbox (measured data: no mesh, arm or sensor)."""
        for name, box in self.layers.items():
            box.visible = name in names

    def sync_layers(self, layers: dict[str, bool]) -> None:
        with self.syncing.quiet():
            for name, box in self.layers.items():
                if name in layers:
                    box.value = bool(layers[name])


#: The lesson's row of buttons: one viser button group, Previous and Next side by side above the step's text. The
#: row never changes (a button moving under a quick second click would press its neighbour); Next at the last step
#: stays there, as Previous at the first does.
LESSON_PREVIOUS, LESSON_NEXT = "Previous", "Next"


class LearnPanel:
    """Learn tab: the nine-step lesson's text and its buttons."""

    def __init__(self, gui, app: Actions):
        # Previous and Next on one row, then the text: on a projector (1280x720, large text) both buttons and the
        # text's start are in view without scrolling at every step
        self.lesson_nav = gui.add_button_group("Lesson", (LESSON_PREVIOUS, LESSON_NEXT))
        self.lesson = gui.add_markdown(
            "The nine steps of RRBC, one at a time, each shown in the scene with live numbers. Press **Next** to start."
        )
        self.lesson_end = gui.add_button("End lesson (restore layers)")
        steps = {LESSON_NEXT: +1, LESSON_PREVIOUS: -1}
        self.lesson_nav.on_click(
            lambda event: app.views.lesson_step(steps[event.target.value]) if event.target.value in steps else None
        )
        self.lesson_end.on_click(lambda event: app.views.lesson_stop())
        self.bullseye = Bullseye(gui)

    def show_text(self, markdown: str) -> None:
        """The lesson step's text (or the prompt to start)."""
        self.lesson.content = markdown


class MonteCarloPanel:
    """Monte Carlo tab: what ran, the trials, and the two plots."""

    def __init__(self, gui, app: Actions, syncing: Syncing):
        self.mc_info = gui.add_markdown("")
        self.mc_trials = gui.add_slider("Trials", 20, 1000, 10, 200)
        self.mc_run = gui.add_button("Run again")
        self.mc_stop = gui.add_button("Stop", disabled=True, hint="Stop the Monte Carlo run under way")
        z2 = (np.array([0.0, 1.0]), np.zeros(2), np.zeros(2))
        self.mc_hist = gui.add_uplot(
            z2,
            ({"label": "error (mm)"}, _series("rigid", "#dc2828"), _series("RRBC", "#1eb43c")),
            title="Error at check points: histogram",
            scales={"x": {"time": False}},
            axes=({"label": "error (mm)"}, {"label": "fraction"}),
            aspect=1.4,
        )
        self.mc_dist = gui.add_uplot(
            (np.array([0.0, 1.0]),) + (np.zeros(2),) * 6,
            (
                {"label": "distance (mm)"},
                _series("rigid", "#dc2828", True),
                _series("RRBC", "#1eb43c", True),
                _band("rigid 95 % low", "#dc2828"),
                _band("rigid 95 % high", "#dc2828"),
                _band("RRBC 95 % low", "#1eb43c"),
                _band("RRBC 95 % high", "#1eb43c"),
            ),
            title="Mean error vs distance from the origin (binned, 95 % intervals)",
            scales={"x": {"time": False}},
            axes=({"label": "distance from origin (mm)"}, {"label": "mean error (mm)"}),
            aspect=1.4,
        )
        self.mc_run.on_click(lambda event: app.montecarlo.request(new_noise=True, trials=self.trials()))
        self.mc_stop.on_click(lambda event: app.montecarlo.stop())

        @self.mc_trials.on_update
        def _(event: viser.GuiEvent) -> None:
            if not syncing.on:
                app.montecarlo.request(trials=self.trials())

    def trials(self) -> int:
        """The trials the slider shows (a value a tab sent is clamped to the slider's range)."""
        return int(clamped(self.mc_trials))

    def show_info(self, markdown: str) -> None:
        """What ran (trials, setup, time) or why nothing did."""
        self.mc_info.content = markdown

    def set_running(self, running: bool) -> None:
        """Stop is offered while a run is under way."""
        self.mc_stop.disabled = not running


def _controller_of(app: Actions, name: str) -> Callable[[], Any]:
    """A function returning the plug-in tab `name`'s controller (built after its panel)."""
    return lambda: app.tabs[name]


class Controls:
    """The control panel: the status line and the tabs, one panel each (module docstring)."""

    def __init__(self, server: Stage, app: Actions, plugins: Sequence[TabPanel] = ()):
        self.app = app
        self.syncing = Syncing()
        gui = server.gui
        self.gui = gui
        self.apply_theme(presentation=False)
        gui.set_panel_label("RRBC explorer")
        self.style = gui.add_html(NORMAL_CSS)  # the panel's style sheet (presentation mode: large text)
        self.status = gui.add_markdown("")
        self.headline = gui.add_html("")  # rigid → RRBC, above the tabs (tables.headline)
        # the colour legend, collapsible: open while exploring, closed in presentation mode (a lesson needs the room)
        with gui.add_folder("Colours", expand_by_default=True) as self.legend_open:
            self.legend = gui.add_html(legend_html())
        with gui.add_folder("Colours", expand_by_default=False, visible=False) as self.legend_closed:
            self.legend_closed_html = gui.add_html(legend_html())
        tabs = self._tab_group = gui.add_tab_group()
        with tabs.add_tab("Explore", icon=viser.Icon.ADJUSTMENTS):
            self.selection = SelectionPanel(gui, app, self.syncing)
            self.explore = ExplorePanel(gui, app, self.syncing)
            self.checks = ChecksPanel(gui)
        with tabs.add_tab("View", icon=viser.Icon.EYE):
            self.view = ViewPanel(gui, app, self.syncing)
        with tabs.add_tab("Learn", icon=viser.Icon.SCHOOL):
            self.learn = LearnPanel(gui, app)
        with tabs.add_tab("Monte Carlo", icon=viser.Icon.CHART_HISTOGRAM):
            self.montecarlo = MonteCarloPanel(gui, app, self.syncing)
        #: the plug-in tabs' panels by name (each handed a function returning its controller, built after it)
        self.tabs: dict[str, Any] = {}
        for name, label, icon, panel in plugins:
            with tabs.add_tab(label, icon=getattr(viser.Icon, icon)):
                self.tabs[name] = panel(gui, _controller_of(app, name))
        with tabs.add_tab("Arm (VEC)", icon=viser.Icon.ROBOT):
            self.vec = VecPanel(gui, app, self.syncing)
        with tabs.add_tab("Plan", icon=viser.Icon.MAP_PIN):
            self.plan = PlanningPanel(server, app)
        with tabs.add_tab("File", icon=viser.Icon.FOLDER_OPEN):
            self.file = FilePanel(gui, app)
            self.authoring = AuthoringPanel(gui, app)

    def apply_theme(self, presentation: bool) -> None:
        """The panel's theme. Presentation mode makes its text large (PRESENTATION_CSS: the panel's sizes are in
        rem, so a larger root font scales them). The panel floats over the view in both modes and collapses with
        its own minimise control (the view then takes the whole screen)."""
        self.gui.configure_theme(show_share_button=False, control_width="large", brand_color=(40, 120, 255))
        self.gui.main_panel.set_width(PRESENTATION_PANEL_WIDTH_PX if presentation else PANEL_WIDTH_PX)
        if hasattr(self, "style"):
            self.style.content = PRESENTATION_CSS if presentation else NORMAL_CSS

    def tab_labels(self) -> tuple[str, ...]:
        """The tab bar's labels, in order."""
        return tuple(self._tab_group._tab_labels)

    def show_legend(self, open_: bool | None) -> None:
        """The colour legend open (exploring), closed to its title (a lesson) or, None, not shown (presentation mode:
        a projector needs the room; a lesson's text names the colours it shows)."""
        self.legend_open.visible = open_ is True
        self.legend_closed.visible = open_ is False

    # -------------------------------------------------------------------------------- what the app shows here
    def show_headline(self, html: str) -> None:
        """The rigid → RRBC readout above the tabs (tables.headline); hidden when empty."""
        if self.headline.content != html:
            self.headline.content = html
        self.headline.visible = bool(html)

    def show_status(self, line: str) -> None:
        """The status line at the top of the panel (the last message)."""
        self.status.content = line

    def show_monte_carlo_plots(self, visible: bool, histogram=None, by_distance=None) -> None:
        """Show or hide the Monte Carlo tab's plots and controls (hidden for measured data: no error model to
        simulate); with data, (centres, rigid, rrbc) and (distance, rigid, rrbc, and their intervals' edges)."""
        mc = self.montecarlo
        mc.mc_hist.visible = mc.mc_dist.visible = mc.mc_trials.visible = mc.mc_run.visible = bool(visible)
        mc.mc_stop.visible = bool(visible)
        if histogram is not None:
            mc.mc_hist.data = histogram
        if by_distance is not None:
            mc.mc_dist.data = by_distance

    # -------------------------------------------------------------------------------------------- syncing
    def quiet(self):
        """Assign GUI values without acting on them."""
        return self.syncing.quiet()

    def sync_settings(self, settings: Settings, kind: str) -> None:
        self.explore.sync(settings, kind)

    def sync_display(self, display: Display, kind: str) -> None:
        self.explore.sync(None, kind, display)
        self.view.sync(display, kind)

    def sync_layers(self, layers: dict[str, bool]) -> None:
        """Show the layer visibilities on the checkboxes (the app applies them to the scene)."""
        self.view.sync_layers(layers)

    def sync_slice(self, display: Display, offsets: tuple[float, float], kind: str, offset: float) -> None:
        """The slice's controls: its value (the choices that apply to `kind`), axis, and `offset` (mm, the plane's
        place) within `offsets`."""
        v = self.view
        with self.syncing.quiet():
            scene = tuple(k for k, _ in SLICE_CHOICES)
            v.slice_value.options = scene if kind == "scene" else scene[2:]
            v.slice_value.value = next(k for k, x in SLICE_CHOICES if x == display.slice_value)
            v.slice_axis.value = next(k for k, x in SLICE_AXES if x == display.slice_axis)
            lo, hi = float(np.floor(offsets[0])), float(np.ceil(offsets[1]))
            v.slice_offset.min, v.slice_offset.max = lo, hi
            v.slice_offset.value = float(np.clip(round(offset), lo, hi))

    def sync_authoring(self, can_undo: bool, can_redo: bool) -> None:
        """The Edit folder's undo/redo buttons (and its scene-only controls, for the current source)."""
        s = self.app.session
        pose = s.sensor_to_robot if s.kind == "scene" else None
        self.authoring.sync(can_undo, can_redo, s.kind == "scene", None if pose is None else pose.translation)

    def sync_presentation(self, on: bool) -> None:
        with self.syncing.quiet():
            self.view.presentation.value = bool(on)

    def sync_see_through(self, on: bool) -> None:
        with self.syncing.quiet():
            self.view.see_through.value = bool(on)

    def sync_selection(self, choices: tuple[str, ...], value: str, selected) -> None:
        """The selection dropdown's choices and value (selection_card.point_names / choice_of)."""
        self.selection.sync(choices, value, selected)

    def show_bullseye(self, svg: str | None, caption: str = "", key: str = "", where: str = "explore") -> None:
        """Show a landing bullseye (selection_card.bullseye_svg) in the Explore or the Learn tab, or hide it."""
        (self.selection if where == "explore" else self.learn).bullseye.show(svg, caption, key)
