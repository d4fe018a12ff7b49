"""The Plan tab: fiducial placement (issue 7) shown over the core's planning (`rrbc_core.analysis.planning` through the
session's `planning_state`, `suggest_fiducials` and `accept_suggestions`).

What the user sees:
- the predicted RMST over the targets' regions of variability, rigid only and with RRBC (± its 1σ), and each
  target's coverage (the fraction of its region inside the included fiducials' hull), for the fiducials as they
  are now: it follows drags of fiducials and targets (recomputed at most every `PLAN_INTERVAL_S` while dragging,
  and at a drag's end; when an update takes longer than `PLAN_LIVE_MAX_S` (large scenes), drags hand it to a
  background thread instead, which computes it whenever the drag pauses for `PLAN_QUIET_S` or ends), exclusions,
  noise/bias sizes and accepted suggestions;
- "Colour regions by coverage": each target's region, and a translucent halo around the target (visible from
  afar, where a region of a few mm is a pixel), on the coverage scale of `colors.coverage_colors`;
- "Suggest": K more fiducials from the scene's candidates (the planner's greedy + exchange), drawn as ghost
  spheres labelled +1 … +K with the predicted gain; "Accept suggestions" makes them fiducials (measured from the
  error model like any fiducial), "Clear suggestions" removes the ghosts.

Measured data have no error model and no candidates: the tab says so and hides its buttons.

Nodes: /plan (group), /plan/ghosts/<k> (icosphere) with /plan/ghosts/<k>/label, and per target
/targets/<id>/gizmo/coverage (a halo that follows the target's gizmo in the browser with no round trip).
The panel owns its widgets and the ghosts' nodes and offers verbs; what it shows is decided by the Plan controller
(`controllers.plan.PlanController`: the planning state, its throttle and background worker). Formatting only here:
every number comes from the core.
"""

from __future__ import annotations

from contextlib import contextmanager
from typing import TYPE_CHECKING

import numpy as np
import viser

from rrbc_core.analysis.planning_coverage import DEFAULT_REGION_MM
from rrbc_core.session.results import PlanningState
from rrbc_core.session.tolerance_plan import MIN_TOLERANCE_MM, tolerance_text

from . import colors

if TYPE_CHECKING:
    from .actions import Actions
    from .stage import Stage

K_MAX = 10
GHOST_MARKERS = 1.4  # ghost sphere radius, in marker radii (a fiducial is 1)
PROMPT_SUGGEST = (
    "Press **Suggest** for K more fiducials from the scene's candidate locations (those the sensor "
    "cannot see or that lie inside solid geometry are never suggested)."
)

PROMPT_TOLERANCE = (
    "Give the largest 95 % bound you can accept on a target's error and press **Fewest fiducials for it**: the "
    "fewest of the scene's candidate locations that bring every target under it, or what limits them."
)


def pct(fraction: float) -> str:
    """A coverage fraction as a percentage; 100 % only when it is complete (0.9995 shows as 99.9 %)."""
    if not np.isfinite(fraction):
        return "—"
    v = float(fraction) * 100.0
    if v < 100.0:
        v = min(v, 99.9)
    return f"{v:.1f} %" if v < 100.0 else "100 %"


def rmst_pair(pred) -> tuple[str, str]:
    """('0.530 ± 0.0004 mm', …) for rigid and RRBC of a planning.RmstPrediction (the std is often < 1 µm)."""
    return (f"{pred.rigid_mm:.3f} ± {pred.rigid_std_mm:.4f} mm", f"{pred.rrbc_mm:.3f} ± {pred.rrbc_std_mm:.4f} mm")


def rmst_line(pred) -> str:
    """The one line the panel leads with (and tests look for)."""
    rigid, rrbc = rmst_pair(pred)
    return f"Predicted RMST: rigid **{rigid}**, RRBC **{rrbc}**"


def method_note(settings) -> str:
    """A warning when the session's method is not the one the planner predicts (least squares + IDW k=4, p=2)."""
    if settings is None:
        return ""
    same = (
        settings.registration == "least-squares"
        and settings.interpolation == "idw"
        and int(settings.neighbors) == 4
        and float(settings.power) == 2.0
    )
    if same:
        return ""
    interp = settings.interpolation + (
        f" (k={settings.neighbors}, p={settings.power:g})" if settings.interpolation == "idw" else ""
    )
    return (
        f"⚠ The session uses {settings.registration} + {interp}; this prediction is for least squares + IDW "
        "(k=4, p=2), the planner's model."
    )


def render_state(state: PlanningState, excluded: int = 0, settings=None, centres=None) -> str:
    """Predicted RMST and how many targets are covered, for the fiducials as they are now (and a note when the
    session's method differs from the planner's). `centres`: the Evaluation's `coverage` (each target inside the
    fiducials' hull or not, as the Explore card and RRBC's extrapolation flag say)."""
    pred = state.predicted
    if pred is None:
        raise ValueError("render_state needs a predicted RMST (scene mode); measured data use render_coverage")
    n_full = int(np.sum(state.coverage >= 1.0))
    short = [f"{pid} {pct(c)}" for pid, c in zip(state.target_ids, state.coverage) if c < 1.0]
    cover = f"**{n_full} of {len(state.target_ids)} regions** fully inside the fiducials' hull"
    if centres is not None:
        n_in = int(np.sum(centres.inside))
        cover = f"**{n_in} of {len(centres.inside)} targets** inside the fiducials' hull; " + cover
    lines = [
        rmst_line(pred) + f" ({pred.method}; over the targets' regions of variability, {state.fiducials_used} "
        f"fiducials{f', {excluded} excluded' if excluded else ''}; least squares + IDW k=4, p=2 as the planner "
        "predicts). Follows drags, exclusions and the noise/bias sizes.",
        "Coverage: " + cover + (f"; ⚠ {', '.join(short)}." if short else "."),
    ]
    note = method_note(settings)
    return "\n\n".join(lines + ([note] if note else []))


PROMPT_MEASURED = (
    "Measured data: **Suggest** proposes places to measure more fiducials so that every target's region lies "
    "inside their hull (coverage first, then spread; no error model needed)."
)


def render_coverage(state: PlanningState, centres=None, ids=()) -> str:
    """Per target: inside the fiducials' hull or not (`centres`, the Evaluation's coverage over `ids`) and the
    fraction of its region of variability inside."""
    where = dict(zip(ids, centres.inside)) if centres is not None else {}
    return "| target | hull | region inside |\n|---|:---:|---:|\n" + "\n".join(
        f"| {pid} | {'inside' if where.get(pid, True) else '⚠ outside'} | {pct(c)}{'' if c >= 1.0 else ' ⚠'} |"
        for pid, c in zip(state.target_ids, state.coverage)
    )


def _baseline_text(baselines: dict) -> str:
    parts = []
    for name, b in (baselines or {}).items():
        rrbc = getattr(b, "rrbc_mm", None)
        if rrbc is None and isinstance(b, dict):
            rrbc = b.get("rrbc_mm")
        if rrbc is not None and np.isfinite(rrbc):
            parts.append(f"{name} {float(rrbc):.3f} mm")
    return ", ".join(parts)


def _rejected_text(rejected: dict) -> str:
    if not rejected:
        return ""
    reasons: dict = {}
    for reason in rejected.values():
        key = str(reason).split(":")[0].strip() or "rejected"
        reasons[key] = reasons.get(key, 0) + 1
    return "; ".join(f"{n} {r}" for r, n in sorted(reasons.items(), key=lambda x: -x[1]))


def render_suggestion(result, current: bool = True) -> str:
    """The suggested fiducials (numbered as their ghosts), the predicted gain, coverage after, the rules it was
    compared with and the candidates rejected; or why nothing (or fewer than asked) is suggested."""
    k = len(result.suggested_ids)
    if k == 0:
        why = (
            f"**Nothing suggested:** {result.note}."
            if getattr(result, "note", "")
            else "⚠ The planner found no usable candidate to add (see the rejected candidates below)."
        )
        uncovered = getattr(result, "uncovered", {}) or {}
        why += "".join(f"\n\n- **{tid}**: {u['reason']}." for tid, u in uncovered.items())
        return why + (f"\n\nRejected candidates: {_rejected_text(result.rejected)}." if result.rejected else "")
    b, a = result.predicted, result.predicted_after
    rows = "\n".join(
        f"| +{i + 1} | {cid} | {p[0]:.0f}, {p[1]:.0f}, {p[2]:.0f} |"
        for i, (cid, p) in enumerate(zip(result.suggested_ids, np.asarray(result.suggested)))
    )
    cov_after = np.asarray(result.coverage_after, float)
    short = [f"{pid} {pct(c)}" for pid, c in zip(result.target_ids, cov_after) if c < 1.0]
    change = (a.rrbc_mm / b.rrbc_mm - 1.0) * 100.0 if b.rrbc_mm > 0 else 0.0
    lines = [] if current else ["**(made for the fiducials as they were — press Suggest again)**"]
    lines += [
        f"**Suggested: {k} fiducial{'s' if k != 1 else ''}** (ghost spheres +1 … +{k}):",
        "| # | candidate | x, y, z (mm) |\n|---|---|---|\n" + rows,
        f"Predicted RMST after: rigid {b.rigid_mm:.3f} → **{a.rigid_mm:.3f} ± {a.rigid_std_mm:.4f} mm**, RRBC "
        f"{b.rrbc_mm:.3f} → **{a.rrbc_mm:.3f} ± {a.rrbc_std_mm:.4f} mm** (RRBC {change:+.0f} %).",
        "Coverage after: " + ("every target 100 %." if not short else ", ".join(short) + "."),
    ]
    uncovered = getattr(result, "uncovered", {}) or {}
    if (
        uncovered
    ):  # why a region stays partly outside and where a fiducial would be needed (`planning.uncovered_reasons`)
        lines.append("\n".join(f"- **{tid}**: {why['reason']}." for tid, why in uncovered.items()))
    if getattr(result, "requested", k) > k:  # fewer than asked: only these are predicted to help
        lines.insert(len(lines) - 2, f"⚠ {result.note}.")
    base = _baseline_text(result.baselines)
    if base:
        lines.append(f"Simple rules with the same K (predicted RMST with RRBC): {base}.")
    rej = _rejected_text(result.rejected)
    if rej:
        lines.append(f"Candidates never suggested: {rej}.")
    return "\n\n".join(lines)


class PlanningPanel:
    """The Plan tab's widgets (built inside the tab by `Controls`) and its ghosts' nodes (module docstring)."""

    def __init__(self, server: Stage, app: Actions):
        self._server = server
        gui = server.gui
        self.info = gui.add_markdown("")
        self.k = gui.add_slider("Fiducials to add (K)", 1, K_MAX, 1, 4)
        self.suggest_button = gui.add_button(
            "Suggest", icon=viser.Icon.WAND, hint="Choose K more fiducials from the scene's candidate locations"
        )
        self.suggestion_md = gui.add_markdown(PROMPT_SUGGEST)
        self.accept_button = gui.add_button(
            "Accept suggestions", icon=viser.Icon.CHECK, disabled=True, hint="Add the suggested fiducials to the cell"
        )
        self.clear_button = gui.add_button("Clear suggestions", icon=viser.Icon.TRASH, disabled=True)
        self.undo_button = gui.add_button(
            "Undo",
            icon=viser.Icon.ARROW_BACK_UP,
            disabled=True,
            hint="Undo the last change to the cell (accepted suggestions, added or deleted points): the same history as "
            "the File tab's Undo",
        )
        with gui.add_folder("To a tolerance"):
            self.tolerance = gui.add_number(
                "Tolerance (mm)",
                0.5,
                min=MIN_TOLERANCE_MM,
                step=0.01,
                hint="The largest 95 % bound on a target's error you can accept (rrbc plan --tolerance)",
            )
            self.tolerance_button = gui.add_button(
                "Fewest fiducials for it",
                icon=viser.Icon.TARGET,
                hint="Choose the fewest of the scene's candidate locations that bring every target's 95 % bound under "
                "the tolerance, or say what limits it",
            )
            self.tolerance_md = gui.add_markdown(PROMPT_TOLERANCE)
            self.use_plan_button = gui.add_button(
                "Use these fiducials",
                icon=viser.Icon.CHECK,
                disabled=True,
                hint="Replace the cell's fiducials by the planned ones (Undo brings them back)",
            )
        with gui.add_folder("Coverage"):
            self.colour = gui.add_checkbox(
                "Colour regions by coverage",
                False,
                hint="Each target's region of variability and a halo around the target, "
                "coloured by the fraction of the region inside the fiducials' hull",
            )
            self.legend = gui.add_markdown(colors.coverage_legend_markdown())
            self.coverage_md = gui.add_markdown("")
        self.ghosts: list = []  # icosphere handles of the suggested fiducials
        self.ghost_labels: list = []
        self._sent: dict = {}  # (id(handle), attr) -> value last assigned
        self._group: viser.FrameHandle | None = None
        self._syncing = False

        @self.colour.on_update
        def _(event: viser.GuiEvent) -> None:
            if not self._syncing:
                app.plan.set_coverage_colours(bool(self.colour.value))

        @self.suggest_button.on_click
        def _suggest(event: viser.GuiEvent) -> None:
            app.plan.suggest_fiducials(k=self.chosen_k(), client=event.client)

        @self.accept_button.on_click
        def _accept(event: viser.GuiEvent) -> None:
            app.plan.accept_suggestions(client=event.client)

        @self.clear_button.on_click
        def _clear(event: viser.GuiEvent) -> None:
            app.plan.clear_suggestions()

        @self.tolerance_button.on_click
        def _tolerance(event: viser.GuiEvent) -> None:
            app.plan.plan_tolerance(self.tolerance.value, client=event.client)

        @self.use_plan_button.on_click
        def _use(event: viser.GuiEvent) -> None:
            app.plan.use_tolerance_plan(client=event.client)

        @self.undo_button.on_click
        def _undo(event: viser.GuiEvent) -> None:
            app.authoring.undo(client=event.client)

    def chosen_k(self) -> int:
        """The K the slider shows (within 1..K_MAX)."""
        return int(np.clip(round(float(self.k.value)), 1, K_MAX))

    @contextmanager
    def quiet(self):
        """Assign GUI values without acting on them."""
        was, self._syncing = self._syncing, True
        try:
            yield
        finally:
            self._syncing = was

    # ------------------------------------------------------------------------------------------ building
    def build(self, scene_mode: bool) -> None:
        """(Re)create the tab's nodes for a newly installed source (call after SceneNodes.build, in atomic())."""
        self._sent.clear()
        self.ghosts, self.ghost_labels = [], []
        if self._group is not None:
            try:
                self._group.remove()
            except Exception:  # noqa: BLE001 - already gone
                pass
        self._group = self._server.scene.add_frame("/plan", show_axes=False)
        for h in (self.colour, self.accept_button, self.clear_button):
            h.disabled = not scene_mode
            h.visible = scene_mode  # measured data: suggestions are places to measure, not fiducials to add
        tolerance_widgets: tuple = (self.tolerance, self.tolerance_button, self.tolerance_md, self.use_plan_button)
        for w in tolerance_widgets:
            w.visible = scene_mode  # a plan to a tolerance needs the scene's error model
        self.tolerance_button.disabled, self.use_plan_button.disabled = False, True
        self.tolerance_md.content = PROMPT_TOLERANCE
        self.k.disabled = self.suggest_button.disabled = False
        self.k.visible = self.suggest_button.visible = True
        self.accept_button.disabled = self.clear_button.disabled = True
        self.suggestion_md.content = PROMPT_SUGGEST if scene_mode else PROMPT_MEASURED

    def _assign(self, handle, attr: str, value) -> None:
        key = (id(handle), attr)
        if self._sent.get(key) == value:
            return
        setattr(handle, attr, value)
        self._sent[key] = value

    # ------------------------------------------------------------------------------------------ showing
    def show_planning(self, info: str, coverage: str) -> None:
        """The tab's lead text (predicted RMST, coverage counts, or why it cannot plan) and the per-target table."""
        self._assign(self.info, "content", info)
        self._assign(self.coverage_md, "content", coverage)

    def show_failure(self, text: str) -> None:
        """Planning failed: say why; the next state shown is sent whole."""
        self.info.content = text
        self.coverage_md.content = ""
        self._sent.clear()

    def refresh_suggestion(self, result, current: bool) -> None:
        """Re-render a suggestion whose ghosts are shown (it may have become stale: Accept only while current)."""
        if self.ghosts:
            self._assign(self.suggestion_md, "content", render_suggestion(result, current))
            self._assign(self.accept_button, "disabled", not current)

    def sync_colour(self, on: bool) -> None:
        """The "Colour regions by coverage" box, set without acting on it."""
        if bool(self.colour.value) != bool(on):
            with self.quiet():
                self.colour.value = bool(on)  # type: ignore[misc]  # viser's stub: a checkbox's value is settable

    def set_busy(self, busy: bool, k: int = 0) -> None:
        """A Suggest is running (its button off and a note) or not."""
        self.suggest_button.disabled = busy
        if busy:
            self.suggestion_md.content = f"Planning: choosing {k} of the scene's candidate locations…"

    def show_progress(self, k: int, extra: str) -> None:
        """The planner's progress (its last label)."""
        self.suggestion_md.content = f"Planning: choosing {k} of the scene's candidate locations… {extra}".rstrip()

    def _add_ghosts(self, ids, positions, marker_mm: float, added: bool = True) -> None:
        """Ghost spheres +1 … +K (labelled with their ids; without `added`, the ids alone: a set that replaces the
        fiducials) at `positions` (K, 3), robot frame, mm."""
        self.remove_ghosts()
        r = marker_mm
        for i, (cid, p) in enumerate(zip(ids, np.asarray(positions, float).reshape(-1, 3))):
            name = f"/plan/ghosts/{i}"
            self.ghosts.append(
                self._server.scene.add_icosphere(
                    name,
                    radius=GHOST_MARKERS * r,
                    color=colors.GHOST,
                    subdivisions=2,
                    opacity=colors.GHOST_OPACITY,
                    position=np.asarray(p, float),
                    cast_shadow=False,
                    receive_shadow=False,
                )
            )
            self.ghost_labels.append(
                self._server.scene.add_label(
                    f"{name}/label",
                    f"+{i + 1} {cid}" if added else str(cid),
                    position=(0.0, 0.0, 2.0 * r),
                    font_size_mode="screen",
                    font_screen_scale=0.75,
                    anchor="bottom-left",
                )
            )

    def set_tolerance_busy(self, busy: bool, tolerance_mm: float = 0.0) -> None:
        """A plan to a tolerance is being computed (its button off and a note) or not."""
        self.tolerance_button.disabled = busy
        if busy:
            self.tolerance_md.content = f"Planning: the fewest fiducials for {tolerance_mm:g} mm…"

    def show_tolerance_progress(self, tolerance_mm: float, label: str) -> None:
        """How far the plan to a tolerance being computed has come (`plan_to_tolerance`'s progress label)."""
        self.tolerance_md.content = f"Planning the fewest fiducials for {tolerance_mm:g} mm… {label}"

    def show_tolerance_plan(self, plan, marker_mm: float) -> None:
        """A plan to a tolerance: its fiducials as ghost spheres, its text (`rrbc plan --tolerance`'s), and Use."""
        self._add_ghosts(plan.fiducial_ids, plan.fiducial_positions, marker_mm, added=False)
        self.tolerance_md.content = tolerance_markdown(plan)
        self.use_plan_button.disabled = not len(self.ghosts)
        self.clear_button.disabled = not len(self.ghosts)

    def show_tolerance_refusal(self, message: str) -> None:
        """Why the last plan to a tolerance was refused."""
        self.tolerance_md.content = f"⚠ Cannot plan: {' '.join(str(message).split())}"

    def show_refusal(self, message: str) -> None:
        """Why the last Suggest was refused."""
        self.suggestion_md.content = f"⚠ Cannot suggest: {' '.join(str(message).split())}"

    def sync_undo(self, can_undo: bool) -> None:
        """Enable Undo while the session has an edit to undo."""
        self.undo_button.disabled = not can_undo

    def show_suggestion(self, result, current: bool, marker_mm: float) -> None:
        """Ghost spheres +1 … +K at the suggested places and the suggestion's text. Accept is offered only for a
        suggestion made for the fiducials as they are (`current`: the planner never suggests a set predicted worse
        than the current one, but a stale suggestion may be)."""
        self._add_ghosts(result.suggested_ids, result.suggested, marker_mm)
        self.suggestion_md.content = render_suggestion(result, current)
        has = len(self.ghosts) > 0
        self.accept_button.disabled = not (has and current)
        self.clear_button.disabled = not has

    def show_coverage_suggestion(self, plan, marker_mm: float) -> None:
        """Measured data: ghost spheres at the places to measure more fiducials, and what coverage they give."""
        self._add_ghosts(plan.suggested_ids, plan.suggested, marker_mm)
        rows = "\n".join(f"| +{i + 1} | {', '.join(f'{v:.0f}' for v in p)} |" for i, p in enumerate(plan.suggested))
        full = int(np.sum(plan.coverage_after >= 1.0))
        self.suggestion_md.content = (
            f"**Measure {len(plan.suggested)} more fiducials here** (coverage first, then spread; from "
            f"{plan.candidate_source}):\n\n| # | x, y, z (mm) |\n|---|---|\n{rows}\n\n"
            f"Coverage after: {full} of {len(plan.target_ids)} targets fully inside "
            f"(mean {np.mean(plan.coverage):.0%} → {np.mean(plan.coverage_after):.0%}). Measure them in both frames "
            "and add the rows to your file (role fiducial)."
        )

    def remove_ghosts(self, prompt: bool = False) -> None:
        for h in self.ghost_labels + self.ghosts:
            try:
                h.remove()
            except Exception:  # noqa: BLE001 - already gone
                pass
        self.ghosts, self.ghost_labels = [], []
        self.accept_button.disabled = self.clear_button.disabled = self.use_plan_button.disabled = True
        if prompt:
            self.suggestion_md.content = PROMPT_SUGGEST
            self.tolerance_md.content = PROMPT_TOLERANCE


def tolerance_markdown(plan) -> str:
    """The tab's text for a plan to a tolerance: what `rrbc plan --tolerance` prints (`tolerance_text`: its lead line
    word for word, one answer), as wrapped text and tables that fit the panel."""
    lines = tolerance_text(plan).splitlines()
    j = plan.to_json()
    fids = "\n".join(f"| {f['id']} | {', '.join(f'{v:.0f}' for v in f['position'])} |" for f in j["fiducials"])

    def target_row(t: dict) -> str:
        bound = "-" if t["bound95_mm"] is None else f"{t['bound95_mm']:.3f}"
        return f"| {t['id']} | {bound} | {'under' if t['under'] else (t['limit'] or '')} |"

    tgts = "\n".join(target_row(t) for t in j["targets"])
    why = (
        ""
        if plan.met
        else "\n\n*instrument*: the readings' own noise; *registration*: the transform's uncertainty; *interpolation*: "
        "the correction between the fiducials; *reach*: no fiducial near enough for a bound."
    )
    return (
        f"**{lines[0]}**{why}\n\n| fiducial | x, y, z (mm) |\n|---|---|\n{fids}\n\n"
        f"| target | 95 % bound (mm) | |\n|---|---|---|\n{tgts}\n\nEach bound is the median over {plan.draws} noise "
        "draws of this layout: one measurement's bound may come out a little above or below it.\n\n"
        "**Use these fiducials** replaces the cell's."
    )


def measured_info(n_in: int, n_targets: int, full: int, n_regions: int) -> str:
    """The lead text for measured data (no error model: coverage only)."""
    return (
        f"Measured data (no error model, so no predicted RMST). **{n_in} of {n_targets} targets** "
        f"inside the fiducials' hull; **{full} of {n_regions} regions** (each taken as a "
        f"{DEFAULT_REGION_MM:g} mm cube: measured targets carry none) fully inside."
    )


def failure_text(exc: Exception) -> str:
    """Why the Plan tab shows no state."""
    from rrbc_core.errors import InputError

    what = "Cannot plan" if isinstance(exc, InputError) else f"Planning failed: internal error {type(exc).__name__}"
    return f"⚠ {what}: {' '.join(str(exc).split())}"
