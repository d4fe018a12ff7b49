"""What the app does for its tabs besides drags and settings: diagnose the current data, plan (suggest, accept,
clear), run the Monte Carlo in the background, open and export files. Part of `RunningApp` (`app.py`)."""

from __future__ import annotations

import copy
import json
import traceback

import numpy as np

from rrbc_core.analysis.diagnosis import Diagnosis
from rrbc_core.errors import InputError
from rrbc_core.session import authoring, data_set, planning_view, views
from rrbc_core.session.data_set import data_key
from rrbc_core.session.evaluation import Evaluation

from . import diagnosis_panel, files
from .syncing import clamped


class TabActions:
    """Part of `RunningApp` (see there); split out to keep modules short."""

    # ------------------------------------------------------------------------------------------ diagnosis
    def run_diagnosis(self, client=None) -> Diagnosis | None:
        """Diagnose the session's data set (`ExplorerSession.data()`: the file as opened or edited, or the scene's
        simulated data set as the CSV download writes it) and show, in the Diagnose tab, exactly the lines
        `rrbc diagnose` prints for it. The data are taken under the lock; the diagnosis (seconds on a scene with
        an arm) runs outside it, so drags go on. Returns None (and says why in the tab) on InputError."""
        with self._lock:
            session = self.session
            key = data_key(session)
            try:
                data = data_set.session_data(session)
            except InputError as exc:
                data, error = None, str(exc)
        result, text = None, ""
        if data is not None:
            try:
                result = data.diagnose()
            except InputError as exc:
                text = diagnosis_panel.render_error(str(exc))
            except Exception as exc:  # noqa: BLE001 - keep serving
                traceback.print_exc()
                text = diagnosis_panel.render_error(f"internal error: {type(exc).__name__}: {exc}")
            else:
                text = diagnosis_panel.render(result, data)
        else:
            text = diagnosis_panel.render_error(error)
        with self._lock:
            if self.session is not session:  # another source was loaded meanwhile
                return None
            self.diagnosis = result
            self.diagnosis_data = data
            self._diagnosis_key = key
            self._diagnosis_text = text
            self.diagnosis_stale = False
            with self.server.atomic():
                self.controls.text["diagnosis"] = text
            self._check_diagnosis()  # the data changed while it ran: say so at once
        if result is None:
            self._message("diagnosis failed: see the Diagnose tab", client, title="Not diagnosed")
        return result

    def _check_diagnosis(self) -> None:
        """Mark the Diagnose tab's content stale once the data set it was computed from changed (caller holds the
        lock): a change of its key (`data_set.data_key`) — a moved or excluded point, a new seed or size — not a
        method change, which leaves the data as they are."""
        if self._diagnosis_key is None or self.diagnosis_stale:
            return
        if data_key(self.session) != self._diagnosis_key:
            self.diagnosis_stale = True
            self.controls.text["diagnosis"] = diagnosis_panel.STALE + "\n\n" + self._diagnosis_text

    # ------------------------------------------------------------------------------------------- planning
    def set_coverage_colours(self, on: bool) -> None:
        """Colour each target's region (and a halo around it) by coverage, or back to the region colour."""
        with self._lock:
            if bool(self.planning.colour.value) != bool(on):
                with self.planning.quiet():
                    self.planning.colour.value = bool(on)
            with self.server.atomic():
                self.planning.apply_colours(self.session)

    def suggest_fiducials(self, k: int | None = None, client=None, seed: int | None = None):
        """Suggest `k` (default: the tab's K) more fiducials for the session as it is now and show them as ghost
        spheres. The planner runs on a snapshot of the session outside the app's lock (a drag meanwhile goes on;
        the suggestion is then marked as made for the old layout). Returns the planning.PlanResult, or None (and
        a visible message) when refused."""
        panel = self.planning
        with self._lock:
            session = self.session
            k = int(clamped(panel.k)) if k is None else k
            if session.kind != "scene":  # measured data: coverage first, then spread (no error model needed)
                try:
                    plan = planning_view.coverage_plan(session, k)
                except InputError as exc:
                    self._message(str(exc), client, title="Cannot plan")
                    return None
                with self.server.atomic():
                    panel.show_coverage_suggestion(plan)
                return plan
            if not panel.begin():
                self._message("a suggestion is already being computed", client, title="Planning")
                return None
            snapshot = copy.copy(session)  # settings and layout are immutable values
        result, error = None, None
        try:
            result = planning_view.suggest_fiducials(snapshot, k, seed=seed, progress=panel.progress)
        except InputError as exc:
            error = str(exc)
        except Exception as exc:  # noqa: BLE001 - keep serving
            traceback.print_exc()
            error = f"internal error: {type(exc).__name__}: {exc}"
        with self._lock:
            panel.end(self.session)
            if self.session is not session:  # another source was loaded meanwhile
                return None
            if error is not None:
                panel.suggestion_md.content = f"⚠ Cannot suggest: {' '.join(error.split())}"
                self._message(error, client, title="Cannot plan")
                return None
            planning_view.adopt_suggestion(session, snapshot)
            with self.server.atomic():
                panel.show_suggestion(session, result)
        return result

    def accept_suggestions(self, client=None) -> Evaluation | None:
        """Add the suggested fiducials to the cell (measured from the error model), remove the ghosts, update
        everything (planning included). None, and a message, when there is nothing to accept."""
        with self._lock:
            before = self.planning.state
            known = set(self.session.layout["fiducials"].ids)
            try:
                ev = planning_view.accept_suggestions(self.session)
            except InputError as exc:
                self._message(str(exc), client, title="Not accepted")
                return None
            new = [pid for pid in ev.fiducial_ids if pid not in known]
            with self.server.atomic():
                self.nodes.add_new_fiducials(ev)
                self.planning.remove_ghosts(prompt=True)
                self._show(ev, heat=True)
                self.controls.sync_authoring(authoring.can_undo(self.session), authoring.can_redo(self.session))
                self.planning.sync_undo(authoring.can_undo(self.session))
            after = self.planning.state
            text = f"Added {len(new)} fiducial{'s' if len(new) != 1 else ''}: {', '.join(new)} (Undo takes them away)."
            if before is not None and after is not None:
                text += (
                    f" Predicted RMST with RRBC {before.predicted.rrbc_mm:.3f} → {after.predicted.rrbc_mm:.3f} mm, "
                    f"rigid {before.predicted.rigid_mm:.3f} → {after.predicted.rigid_mm:.3f} mm."
                )
            self._message(text, client, error=False, title="Fiducials added")
        self.request_monte_carlo()
        return ev

    def clear_suggestions(self) -> None:
        with self._lock:
            planning_view.clear_suggestion(self.session)
            with self.server.atomic():
                self.planning.remove_ghosts(prompt=True)

    # ---------------------------------------------------------------------------------------- Monte Carlo
    def request_monte_carlo(self, new_noise: bool = False) -> bool:
        """Queue a Monte Carlo run of the current setup (scene mode); False when there is no error model.
        new_noise ("Run again"): a fresh noise seed, so the run differs from the last; otherwise the noise is
        seeded by the session's seed (the same setup gives the same plots)."""
        with self._lock:
            if self.session.kind != "scene":
                self.mc.cancel()
                self.controls.text["mc_info"] = (
                    "Monte Carlo needs a scene (an error model to simulate); measured data have none."
                )
                self.controls.show_monte_carlo_plots(False)
                return False
            snapshot = copy.copy(self.session)  # settings and layout are immutable values
            self.controls.show_monte_carlo_plots(True)
            seed = None
            if new_noise:
                self.mc_draw += 1
                seed = int(np.random.default_rng([self.session.settings.seed, self.mc_draw]).integers(2**31 - 1))
            self.mc_seed = seed
            self.mc.request(snapshot, self.controls.monte_carlo_trials, seed)
            return True

    def stop_monte_carlo(self) -> None:
        """The Stop button: forget the queued run and stop the one under way at its next chunk of trials; the
        plots keep the last finished run."""
        with self._lock:
            self.mc.cancel()
            self.controls.montecarlo.mc_stop.disabled = True
            self.controls.text["mc_info"] = "Monte Carlo: stopped (the plots show the last finished run, if any)."

    def _mc_started(self) -> None:
        self.controls.montecarlo.mc_stop.disabled = False
        self.controls.text["mc_info"] = "Monte Carlo: running…"

    def _mc_result(self, plots, error: str | None, seconds: float) -> None:
        c = self.controls
        c.montecarlo.mc_stop.disabled = True
        if plots is None:
            c.text["mc_info"] = f"Monte Carlo failed: {error}"
            return
        centres, rigid, rrbc = plots.histogram()
        dist, mean_rigid, mean_rrbc, half_rigid, half_rrbc = plots.by_distance()
        with self._lock, self.server.atomic():
            self.mc_plots = plots
            self.mc_seconds = seconds
            c.show_monte_carlo_plots(
                True,
                (centres, rigid, rrbc),
                (
                    dist,
                    mean_rigid,
                    mean_rrbc,
                    mean_rigid - half_rigid,
                    mean_rigid + half_rigid,
                    mean_rrbc - half_rrbc,
                    mean_rrbc + half_rrbc,
                ),
            )
            s = self.session.settings
            c.text["mc_info"] = (
                f"{plots.trials} trials × {plots.rigid.shape[1]} check points in the targets' "
                f"regions; {s.registration} + {s.interpolation}; noise ×{s.noise_scale:g}, "
                f"bias ×{s.bias_scale:g} ({seconds:.1f} s); "
                + (
                    f"noise draw {self.mc_draw} (**Run again** draws new noise). "
                    if self.mc_seed is not None
                    else "noise seeded by the session's seed (**Run again** draws new noise). "
                )
                + "Error vs distance: mean over the check points in each distance bin, with its 95 % interval. "
                "Updates after a setting changes, a drag ends or the seed changes."
            )

    # --------------------------------------------------------------------------------------------- files
    def load(self, source=None, mesh=None, client=None) -> bool:
        """Open a scene (.toml) or measurement file (.csv; optional mesh). On bad input the current session
        stays and a message says why; returns whether the file was loaded."""
        try:
            loaded = files.load_source(source, mesh)
        except InputError as exc:
            self._message(str(exc), client, title="File not loaded")
            return False
        except Exception as exc:  # noqa: BLE001 - e.g. OSError: keep serving
            self._message(f"{source}: cannot open: {type(exc).__name__}: {exc}", client, title="File not loaded")
            return False
        self._install(loaded)
        return True

    def load_offered(self, label: str, mesh_label: str | None = None, client=None) -> bool:
        """Open one of the files the File tab offers (`files.Library`), by its label; anything else is refused."""
        try:
            path = self.library.pick(label)
            mesh = None if mesh_label is None else self.library.pick(mesh_label, meshes=True)
        except InputError as exc:
            self._message(str(exc), client, title="File not loaded")
            return False
        return self.load(path, mesh=mesh, client=client)

    def rescan_files(self) -> None:
        """List the offered folders' files again in the File tab."""
        with self._lock:
            self.controls.file.offer(
                [name for name, _ in self.library.sources()], [name for name, _ in self.library.meshes()]
            )

    def load_upload(self, name: str, content: bytes, client=None) -> bool:
        try:
            loaded = files.load_upload(name, content)
        except InputError as exc:
            self._message(str(exc), client, title="Upload not loaded")
            return False
        except Exception as exc:  # noqa: BLE001
            self._message(f"{name}: cannot open: {type(exc).__name__}: {exc}", client, title="Upload not loaded")
            return False
        self._install(loaded)
        return True

    def export(self, what: str) -> tuple[str, bytes]:
        """(file name, content) of "csv" (views.export_measurements(session) as a measurement file) or "json"
        (views.export_json(session))."""
        with self._lock:
            slug = files.slug(self.session.name)
            if what == "csv":
                s = self.session.settings
                text = files.measurements_csv(
                    views.export_measurements(self.session),
                    comments=[
                        f"exported by the rrbc browser app from {self.session.name}",
                        f"settings: registration {s.registration}, interpolation {s.interpolation}, noise x{s.noise_scale:g}, "
                        f"bias x{s.bias_scale:g}, seed {s.seed}",
                    ],
                )
                return f"rrbc-{slug}.csv", text.encode("utf-8")
            if what == "json":
                return f"rrbc-{slug}-results.json", (
                    json.dumps(views.export_json(self.session), indent=2) + "\n"
                ).encode("utf-8")
        raise InputError(f"unknown export '{what}': csv or json")

    def download(self, what: str, client=None) -> tuple[str, bytes] | None:
        """Send an export to `client` (every tab if None) as a file download."""
        try:
            name, content = self.export(what)
        except (InputError, ValueError) as exc:
            self._message(str(exc), client, title="Export failed")
            return None
        if client is not None:
            client.send_file_download(name, content)
        else:
            self.server.send_file_download(name, content)
        return name, content
