"""What the per-point bounds cost (issue 37, item 5), in the user's own process, idle and with a busy core beside it.

- `correct_bounds_1000`: `rrbc correct FILE --json` on 1000 fiducials and 1000 targets, run in this process
  (`rrbc_core.cli.main`: the arguments parsed, the file read, corrected, bounded and printed as JSON; the
  interpreter's start-up, the same with or without, left out), against the same command with its result's JSON
  made without the bounds (`CorrectionResult.to_json(with_bounds=False)`: nothing of the bounds is computed or
  written): goal, the loaded time with bounds at most 2x the time without (ratio = without / with, so >= 0.5). The note adds the in-memory part alone (`correct_measurements` and `to_json`, no file,
  no text), where the bounds' K-fold cross-validation weighs most.
- `drag_bounds_fiducial`: one step of a fiducial's drag in the default scene's session (`ExplorerSession.move`, the
  evaluation the app draws, bounds included) against the same step with the bounds' basis already cached (a
  target's drag: the fiducials did not change); goal: the loaded median with bounds at most 10 ms (the app's drag
  budget, `drag_default_fiducial`).
"""

from __future__ import annotations

import numpy as np
from harness import both, median_time, row

from rrbc_core.correction.pipeline import correct_measurements
from rrbc_core.io.measurements import MeasurementSet
from rrbc_core.simulation.field_data import field_measurements


def _targets_file(n: int) -> MeasurementSet:
    """A field file with n fiducials and n checks, the checks turned into targets."""
    m = field_measurements(5, n_fiducials=n, n_checks=n)
    roles = tuple("target" if r == "check" else r for r in m.roles)
    return MeasurementSet(m.ids, roles, m.sensor, m.robot, m.time, m.lines, m.source)


def correct_bounds(quick: bool) -> list[dict]:
    """Rows `correct_bounds_1000` and `drag_bounds_fiducial` (module docstring)."""
    import contextlib
    import io
    import tempfile
    from functools import partialmethod
    from pathlib import Path
    from unittest import mock

    from rrbc_core.cli import main
    from rrbc_core.correction.pipeline import CorrectionResult
    from rrbc_core.io.measurements_write import write_measurements

    n = 300 if quick else 1000
    mset = _targets_file(n)
    repeats = 3 if quick else 7
    path = Path(tempfile.mkdtemp(prefix="rrbc-bench-")) / "targets.csv"
    write_measurements(path, mset)

    def command() -> None:  # what `rrbc correct FILE --json` does after start-up
        with contextlib.redirect_stdout(io.StringIO()):
            assert main(["correct", str(path), "--json"]) == 0

    no_bounds = partialmethod(CorrectionResult.to_json, with_bounds=False)

    def command_without() -> None:  # the same command, its result's JSON made without the bounds
        with mock.patch.object(CorrectionResult, "to_json", no_bounds):
            command()

    def measure():
        without, _ = median_time(command_without, repeats)
        with_b, _ = median_time(command, repeats)
        return without, with_b

    def measure_memory():
        without, _ = median_time(lambda: correct_measurements(mset).to_json(with_bounds=False), repeats)
        with_b, _ = median_time(lambda: correct_measurements(mset).to_json(), repeats)
        return without, with_b

    (idle_wo, idle_w), (busy_wo, busy_w) = both(measure)
    (mem_wo, mem_w), (mem_busy_wo, mem_busy_w) = both(measure_memory)
    rows = [
        row(
            f"correct_bounds_{n}",
            busy_w,
            "s",
            loaded=busy_w,
            baseline=busy_wo,
            goal="loaded time with bounds <= 2x without",
            met=bool(busy_w <= 2 * busy_wo),
            note=f"`rrbc correct FILE --json` in this process on {n} fiducials and {n} targets (idw): idle "
            f"{idle_w * 1e3:.0f} ms with bounds, {idle_wo * 1e3:.0f} ms without; busy core {busy_w * 1e3:.0f} ms "
            f"with, {busy_wo * 1e3:.0f} ms without. In memory alone (correct_measurements + to_json, no file, no "
            f"text): idle {mem_w * 1e3:.0f} ms with, {mem_wo * 1e3:.0f} ms without; busy core {mem_busy_w * 1e3:.0f} "
            f"ms with, {mem_busy_wo * 1e3:.0f} ms without",
        )
    ]

    from rrbc_core.io.scene import default_scene_path
    from rrbc_core.io.scene_toml import load_scene
    from rrbc_core.session.explorer import ExplorerSession

    session = ExplorerSession.from_scene(load_scene(default_scene_path()))
    session.evaluate()
    fid = session.layout["fiducials"].ids[0]
    start = session.layout["fiducials"].positions[0].copy()
    steps = 30 if quick else 60

    def drag(cached: bool) -> float:
        times = []
        for k in range(steps):
            p = start + np.array([0.5 * (k + 1), 0.0, 0.0])
            if cached:  # the same fiducial position again: the basis is cached, only the points' part runs
                session.move("fiducials", fid, p)
            times.append(median_time(lambda p=p: session.move("fiducials", fid, p), 1)[0])
        session.move("fiducials", fid, start)
        return float(np.median(times))

    def measure_drag():
        return drag(False), drag(True)

    (idle_step, idle_cached), (busy_step, busy_cached) = both(measure_drag)
    rows.append(
        row(
            "drag_bounds_fiducial",
            busy_step,
            "s",
            loaded=busy_step,
            baseline=busy_cached,
            goal="loaded median <= 0.010 s",
            met=bool(busy_step <= 0.010),
            note=f"one step of fiducial {fid}'s drag in the default scene's session, bounds included: idle median "
            f"{idle_step * 1e3:.1f} ms ({idle_cached * 1e3:.1f} ms with the fiducials' part cached, as a target's "
            f"drag); busy core {busy_step * 1e3:.1f} ms ({busy_cached * 1e3:.1f} ms)",
        )
    )
    return rows
