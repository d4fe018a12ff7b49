"""The whole RRBC run on a measurement set: register, correct fiducials, correct targets, score checks.

This is what `rrbc correct` does; the command line only parses options and prints. Units mm; frames as in
the measurement file (sensor_* sensor frame, robot_* robot frame).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from rrbc_core import interpolation, registration
from rrbc_core.correction import metrics
from rrbc_core.correction.bounds import Bounds, correction_bounds
from rrbc_core.correction.check_statistics import CheckStatistics, check_statistics
from rrbc_core.correction.configuration_check import file_configuration_check
from rrbc_core.correction.rrbc import CorrectedPoints, correct_points, fiducial_corrections
from rrbc_core.correction.warnings import Corrected, correction_warnings
from rrbc_core.errors import InputError
from rrbc_core.geometry.transforms import RigidTransform
from rrbc_core.interpolation.auto import AutoChoice
from rrbc_core.interpolation.hull import Coverage, assess_coverage
from rrbc_core.io.id_sets import member_of
from rrbc_core.io.json_rows import Field, rows_text
from rrbc_core.io.json_stream import LazyRows
from rrbc_core.io.measurements import MeasurementSet, PointGroup
from rrbc_core.methods import MethodOptions
from rrbc_core.models.instrument import Instrument
from rrbc_core.runtime.threads import thread_limited


@dataclass(frozen=True, eq=False)
class CorrectionResult:
    """The outcome of `correct_measurements` (frames as in the measurement file; mm).

    Attributes: ``options`` (the `MethodOptions` used), ``registration`` (`Registration`), ``fiducials`` and
    ``fiducial_corrections`` (N, 3) sensor frame, ``targets``/``checks`` (`PointGroup`) with ``targets_corrected`` /
    ``checks_corrected`` (`CorrectedPoints`: correction, robot_rigid, robot_rrbc, extrapolated; None when there are
    none), ``error_rigid`` / ``error_rrbc`` (C,) at the checks. `summary()` gives RMST and max error rigid and with
    RRBC; `to_json()` the JSON of `rrbc correct --json`.
    """

    options: MethodOptions
    registration: registration.Registration
    fiducials: PointGroup
    fiducial_corrections: np.ndarray
    targets: PointGroup
    targets_corrected: CorrectedPoints | None
    checks: PointGroup
    checks_corrected: CorrectedPoints | None
    error_rigid: np.ndarray  # (C,) check-point errors, mm
    error_rrbc: np.ndarray
    #: targets' and checks' coverage (`interpolation.hull.assess_coverage` over the fiducials' sensor readings: the
    #: same test as the extrapolation flags, with the distance from the fiducials' plane); None without fiducials
    targets_coverage: Coverage | None = None
    checks_coverage: Coverage | None = None
    #: with `--interpolation auto`: what cross-validation over the fiducials chose (`interpolation.auto.AutoChoice`)
    choice: AutoChoice | None = None
    #: the rows corrected (for the bounds' noise estimate from repeats) and the instrument given (None: estimated)
    data: MeasurementSet | None = None
    instrument: Instrument | None = None

    @cached_property
    def bounds(self) -> Bounds:
        """Each target's and check's 95 % bound, covariance and budget, rigid and RRBC (`correction.bounds`),
        computed on first use."""
        reg_pts = self.data.points("registration") if self.data is not None else None
        reg_sensor = reg_pts.sensor if reg_pts is not None else np.zeros((0, 3))
        reg_count = reg_pts.count if reg_pts is not None else np.ones(0)
        method = self.choice.method if self.choice is not None else self.options.interpolator()
        points = {
            kind: (group.sensor, group.count, np.zeros(len(group)) if cp is None else cp.off_plane_mm)
            for kind, group, cp in (
                ("targets", self.targets, self.targets_corrected),
                ("checks", self.checks, self.checks_corrected),
            )
        }
        return correction_bounds(
            self.data,
            self.registration.mapping,
            reg_sensor,
            reg_count,
            self.fiducials.sensor,
            self.fiducials.count,
            self.fiducial_corrections,
            method,
            self.options.interpolation_name != "none",
            points,
            self.instrument,
            np.asarray(self.registration.residuals, float).reshape(-1, 3),
            member_of(self.fiducials.ids, reg_pts.ids if reg_pts else ()),
        )

    def interpolation_json(self) -> dict:
        """The ``interpolation`` JSON: the method and its options; with ``auto`` the method chosen, ``selected_by``,
        ``folds`` and the ``cv`` table."""
        return self.choice.to_json() if self.choice is not None else self.options.interpolation_json()

    def summary(self) -> dict:
        if len(self.error_rigid) == 0:
            return {"rmst_rigid_mm": None, "rmst_rrbc_mm": None, "max_rigid_mm": None, "max_rrbc_mm": None}
        return {
            "rmst_rigid_mm": metrics.rmst(self.error_rigid),
            "rmst_rrbc_mm": metrics.rmst(self.error_rrbc),
            "max_rigid_mm": metrics.max_error(self.error_rigid),
            "max_rrbc_mm": metrics.max_error(self.error_rrbc),
        }

    def statistics(self) -> CheckStatistics | None:
        """Before/after statistics of the check errors (`check_statistics`), None without checks."""
        if self.checks_corrected is None or len(self.error_rigid) == 0:
            return None
        c = self.checks_corrected
        return check_statistics(self.checks.ids, c.robot_rigid, c.robot_rrbc, self.checks.robot)

    @cached_property
    def configuration_warning(self) -> str | None:
        """On a file with q1..q6: checks and targets reached in other joint configurations than their nearest
        fiducials (`configuration_check.file_configuration_check`), in words; None otherwise. Computed once."""
        method = self.choice.method if self.choice is not None else self.options.interpolator()
        config = file_configuration_check(self.data) if method.name != "none" else None
        return config.warning("rrbc calibrate with the arm's model (VEC) follows it") if config is not None else None

    def warnings(self, with_bounds: bool = True) -> tuple[str, ...]:
        """One-line warnings on this correction (`correction.warnings.correction_warnings`: wild corrections,
        conflicting nearly coincident fiducials, extrapolated targets and checks), then the bounds' (`bounds`: points
        given no bound and why, an instrument the data contradict)."""
        points = [
            Corrected(kind, group.ids, cp.correction, cov)
            for kind, group, cp, cov in (
                ("target", self.targets, self.targets_corrected, self.targets_coverage),
                ("check", self.checks, self.checks_corrected, self.checks_coverage),
            )
            if cp is not None
        ]
        said = self.configuration_warning
        return (
            correction_warnings(self.fiducials.ids, self.fiducials.sensor, self.fiducial_corrections, points)
            + ((said,) if said else ())
            + (tuple(self.bounds.warnings) if with_bounds else ())
        )

    def _fiducials_json(self, lazy: bool) -> list | LazyRows:
        ids, sensor, corr = self.fiducials.ids, self.fiducials.sensor, self.fiducial_corrections

        def rows(start: int = 0, stop: int | None = None) -> list:
            sl = slice(start, stop)
            return [
                {"id": i, "sensor": s, "correction_mm": e}
                for i, s, e in zip(ids[sl], sensor[sl].tolist(), corr[sl].tolist())
            ]

        if not lazy:
            return rows()

        def make():
            for start in range(0, len(ids), ROWS_PER_CHUNK):
                yield from rows(start, start + ROWS_PER_CHUNK)

        def encoded():  # the same rows' text from the columns (`io.json_rows`)
            for start in range(0, len(ids), ROWS_PER_CHUNK):
                sl = slice(start, start + ROWS_PER_CHUNK)
                fields = [Field("id", ids[sl], "str"), Field("sensor", sensor[sl]), Field("correction_mm", corr[sl])]
                yield rows_text(fields, len(ids[sl]))

        return LazyRows(len(ids), make, encoded)

    def to_json(self, with_bounds: bool = True, lazy: bool = False) -> dict:
        """The JSON object of `rrbc correct --json` (docs/cli.md); `with_bounds` False leaves the per-point bounds out
        (what they cost: benchmarks/bounds_cost.py); `lazy`: the fiducials', targets' and checks' rows as
        `io.json_stream.LazyRows`, made while they are written (`json_chunks`), `ROWS_PER_CHUNK` at a time."""
        reg = self.registration
        bounds = self.bounds if with_bounds else None
        reg_json = {"method": reg.method, **reg.mapping.as_dict(), "fre_rms_mm": reg.fre_rms_mm}
        if isinstance(reg.mapping, RigidTransform):  # a piecewise mapping has no one matrix
            reg_json.update(reg.mapping.export_forms())
        reg_json.update(self.options.registration_json())  # the strategy's options (a seeded one's seed)
        return {
            "registration": reg_json,
            "interpolation": self.interpolation_json(),
            "fiducials": self._fiducials_json(lazy),
            "targets": _rows(lazy, self.targets, self.targets_corrected, bounds=bounds, kind="targets"),
            "checks": _rows(
                lazy,
                self.checks,
                self.checks_corrected,
                self.error_rigid,
                self.error_rrbc,
                bounds=bounds,
                kind="checks",
            ),
            "summary": self.summary(),
            "check_statistics": None if (st := self.statistics()) is None else st.to_json(),
            **({"bounds": bounds.to_json()} if bounds is not None else {}),
            "warnings": list(self.warnings(with_bounds)),
        }


#: rows made at a time by a lazy `to_json` (whole arrays to lists per chunk: a million rows stay cheap and small)
ROWS_PER_CHUNK = 20_000


def _rows(lazy: bool, group: PointGroup, corrected: CorrectedPoints | None, *args, **kwargs) -> list | LazyRows:
    """`_points_json`'s rows, or (lazy) the same rows made `ROWS_PER_CHUNK` at a time when read."""
    if not lazy:
        return _points_json(group, corrected, *args, **kwargs)
    n = 0 if corrected is None else len(group.ids)

    def make():
        for start in range(0, n, ROWS_PER_CHUNK):
            yield from _points_json(group, corrected, *args, start=start, stop=start + ROWS_PER_CHUNK, **kwargs)

    def encoded():  # the same rows' text from the columns
        if corrected is None:
            return
        for start in range(0, n, ROWS_PER_CHUNK):
            yield _points_text(group, corrected, *args, start=start, stop=start + ROWS_PER_CHUNK, **kwargs)

    return LazyRows(n, make, encoded)


def _points_text(
    group: PointGroup,
    corrected: CorrectedPoints,
    err_rigid=None,
    err_rrbc=None,
    *,
    bounds: Bounds | None = None,
    kind: str = "targets",
    start: int = 0,
    stop: int | None = None,
) -> bytes:
    """`_points_json`'s rows as JSON text (ASCII bytes) made from the columns (`io.json_rows`;
    tests/io/test_json_rows.py holds the two equal)."""
    sl = slice(start, stop)
    c = corrected
    ids = group.ids[sl]
    fields = [
        Field("id", ids, "str"),
        Field("sensor", c.sensor[sl]),
        Field("correction_mm", c.correction[sl]),
        Field("robot_rigid", c.robot_rigid[sl]),
        Field("robot_rrbc", c.robot_rrbc[sl]),
        Field("extrapolated", c.extrapolated[sl], "bool"),
    ]
    if c.correction_std is not None:
        fields.append(Field("correction_std_mm", c.correction_std[sl]))
    off = np.asarray(c.off_plane_mm[sl], float)
    fields.append(Field("off_plane_mm", off, present=off > 0))
    if err_rigid is not None:
        e_rigid, e_rrbc = np.asarray(err_rigid, float)[sl], np.asarray(err_rrbc, float)[sl]
        fields += [
            Field("robot_truth", group.robot[sl]),
            Field("error_rigid_mm", e_rigid),
            Field("error_rrbc_mm", e_rrbc),
            Field("rrbc_worse", e_rrbc > e_rigid, "bool"),
        ]
    pb = getattr(bounds, kind) if bounds is not None else None
    pb_rigid = getattr(bounds, kind + "_rigid") if bounds is not None else None
    if pb is not None and pb_rigid is not None:
        for b, suffix, cov in ((pb, "", True), (pb_rigid, "_rigid", False)):
            none = ~np.isfinite(b.bound95_mm[sl])
            fields.append(Field(f"bound95{suffix}_mm", b.bound95_mm[sl], null=none))
            budget = {name: v[sl] for name, v in b.budget_mm.items()}
            fields.append(Field(f"budget{suffix}_mm", budget, "obj", null=none))
            if cov:
                fields.append(Field(f"cov{suffix}_mm2", b.cov_mm2[sl], null=none))
    return rows_text(fields, len(ids))


def _points_json(
    group: PointGroup,
    corrected: CorrectedPoints | None,
    err_rigid=None,
    err_rrbc=None,
    *,
    bounds: Bounds | None = None,
    kind: str = "targets",
    start: int = 0,
    stop: int | None = None,
) -> list:
    """The JSON rows of points `start`..`stop` (default all) of `group`."""
    rows: list[dict] = []
    if corrected is None:
        return rows
    sl = slice(start, stop)
    pb = getattr(bounds, kind) if bounds is not None else None
    pb_rigid = getattr(bounds, kind + "_rigid") if bounds is not None else None
    b_rows = pb.rows_json(start=start, stop=stop) if pb is not None else None
    b_rigid_rows = pb_rigid.rows_json("_rigid", cov=False, start=start, stop=stop) if pb_rigid is not None else None
    c = corrected  # whole arrays to lists once: a million rows stay cheap
    sensor, corr, rigid, rrbc = (a[sl].tolist() for a in (c.sensor, c.correction, c.robot_rigid, c.robot_rrbc))
    extra = c.extrapolated[sl].tolist()
    std = c.correction_std[sl].tolist() if c.correction_std is not None else None
    off = c.off_plane_mm[sl].tolist()
    if err_rigid is not None:
        truth = group.robot[sl].tolist()
        e_rigid, e_rrbc = np.asarray(err_rigid)[sl].tolist(), np.asarray(err_rrbc)[sl].tolist()
    for k, pid in enumerate(group.ids[sl]):
        row = {
            "id": pid,
            "sensor": sensor[k],
            "correction_mm": corr[k],
            "robot_rigid": rigid[k],
            "robot_rrbc": rrbc[k],
            "extrapolated": bool(extra[k]),
        }
        if std is not None:
            row["correction_std_mm"] = std[k]
        if off[k] > 0:
            row["off_plane_mm"] = off[k]
        if err_rigid is not None:
            row["robot_truth"] = truth[k]
            row["error_rigid_mm"] = e_rigid[k]
            row["error_rrbc_mm"] = e_rrbc[k]
            row["rrbc_worse"] = e_rrbc[k] > e_rigid[k]
        if b_rows is not None and b_rigid_rows is not None:
            row.update(b_rows[k])
            row.update(b_rigid_rows[k])
        rows.append(row)
    return rows


@thread_limited
def correct_measurements(
    mset: MeasurementSet, options: MethodOptions | None = None, instrument: Instrument | None = None
) -> CorrectionResult:
    """RRBC on a measurement set: register, correct the fiducials, interpolate to the targets and checks, score.

    Parameters
    ----------
    mset : MeasurementSet
        Registration, fiducial (or both), target and check rows (`read_measurements`).
    options : MethodOptions, optional
        The registration strategy and interpolation (default: least squares + IDW, k = 4, p = 2).
    instrument : Instrument, optional
        The sensor's and robot's reading noise for the per-point bounds (`CorrectionResult.bounds`; default:
        estimated from the data, `correction.bound_inputs.estimate_noise`).

    Returns
    -------
    CorrectionResult
        The registration, fiducial corrections e = Rᵀ(b − t) − s (sensor frame), each target's and check's
        correction and corrected robot-frame position (``targets_corrected.robot_rrbc``, mm), the check errors and
        `summary()`; `to_json()` is the JSON of `rrbc correct --json`.

    Raises
    ------
    InputError
        Unknown method or options, too few or degenerate registration points, no fiducials for an interpolation.
    """
    options = MethodOptions() if options is None else options
    method = options.interpolator()
    reg_pts = mset.points("registration")
    reg = options.register(reg_pts.sensor, reg_pts.robot)
    fid = mset.points("fiducial")
    targets = mset.points("target")
    checks = mset.points("check")
    if len(fid.ids) == 0:
        if options.interpolation_name != "none":
            raise InputError(
                f"{mset.source}: no fiducial rows (role fiducial or both); add fiducials or use --interpolation none"
            )
        corr = np.zeros((0, 3))
        fitted = interpolation.NoCorrection().fit(reg_pts.sensor, np.zeros_like(reg_pts.sensor))
    else:
        corr = fiducial_corrections(reg.mapping, fid.sensor, fid.robot)
        fitted = method.fit(fid.sensor, corr)
    t_corr = correct_points(reg.mapping, fitted, targets.sensor) if len(targets.ids) else None
    c_corr = correct_points(reg.mapping, fitted, checks.sensor) if len(checks.ids) else None
    if c_corr is not None:
        err_rigid = metrics.tre(c_corr.robot_rigid, checks.robot)
        err_rrbc = metrics.tre(c_corr.robot_rrbc, checks.robot)
    else:
        err_rigid = err_rrbc = np.zeros(0)
    t_cov = assess_coverage(fid.sensor, targets.sensor) if len(fid.ids) and len(targets.ids) else None
    c_cov = assess_coverage(fid.sensor, checks.sensor) if len(fid.ids) and len(checks.ids) else None
    choice = getattr(fitted, "choice", None)
    return CorrectionResult(
        options,
        reg,
        fid,
        corr,
        targets,
        t_corr,
        checks,
        c_corr,
        err_rigid,
        err_rrbc,
        t_cov,
        c_cov,
        choice,
        mset,
        instrument,
    )
