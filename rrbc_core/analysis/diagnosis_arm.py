"""The arm in `rrbc diagnose`: with joint values in the file (the columns of the robot model, `io.joints`), an error
of the arm's kinematic parameters is a test like scale or affine (docs/theory.md §6.5).

The model: `--urdf FILE [--tip LINK] [--base LINK]` or `--robot ur5|ur10` (columns q1..q6, degrees), with `--tool`
(`robot_model.robot_chain`). Before the test, the model is held against the file's robot columns
(`robot_model.check_model`): a model chosen on the command line that does not describe the robot is refused (one
line, the disagreement in mm); without a choice, q1..q6 columns are tried as a UR5 and, if the UR5 does not describe
them, the kinematic test is left out and the limits say why — no `kinematic` effect is named with a wrong arm.

Model. A row measured at joints q has the residual r = robot − (R sensor + t) = FK(0, q) − FK(δ, q) ≈ −J(q) δ to
first order, J = ∂FK/∂δ at the nominal arm (`calibration.position_jacobian`: joint offsets, the joints' origins, the
tool point; angles scaled to mm). The test's columns are J at each point (the mean over the point's rows: a point
measured in several configurations has the mean of their errors), and the F-test counts only the combinations these
poses determine beside the rigid (and accepted) terms. A uniform scale lies inside this span (all lengths scaled
together scale the arm), so with joint values a scale that the arm explains is reported as kinematic; an error that
depends on the configuration (the same place reached two ways disagreeing) has no place in any position-only term.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

import numpy as np

from rrbc_core.analysis.calibration import angle_scale, position_jacobian
from rrbc_core.analysis.diagnosis_stats import ftest, usable
from rrbc_core.analysis.robot_model import ModelCheck, check_model, robot_chain
from rrbc_core.errors import InputError
from rrbc_core.io.joints import joint_values
from rrbc_core.io.measurements import MeasurementSet
from rrbc_core.models.loads import candidate_terms, factor_scale, gravity_loads, term_jacobian

MIN_POINTS = 12  # fewer paired points with joints: the kinematic test is not run (said in the limits)


@dataclass(frozen=True, eq=False)
class ArmColumns:
    """Per paired point `fields` (P, N, 3) mm per scaled parameter (the mean over its rows), per paired row
    `row_fields` (R, 3, P), the robot's name, its tip link and tool point (3,) mm, and the model check."""

    fields: np.ndarray
    row_fields: np.ndarray
    robot: str
    tip: str
    tool_mm: tuple
    check: ModelCheck | None
    #: the load terms the data can see (`models.loads.candidate_terms`; empty without link masses), their columns
    #: per point (T, N, 3) and per row (R, 3, T) in mm per scaled coefficient, and the scales (T,) (mm per rad/Nm)
    load_terms: tuple = ()
    load_fields: np.ndarray | None = None
    load_row_fields: np.ndarray | None = None
    load_scales: np.ndarray | None = None
    #: no arm model: the columns are harmonics of the file's joint-like columns (`configuration_columns`), named here
    model_free: tuple[str, ...] = ()


@dataclass(frozen=True)
class ArmModel:
    """The arm's model as `rrbc diagnose` was asked for it: `robot` (ur5, ur10 or None: not chosen), or `urdf` with
    `tip` and `base`; `tool` a length along the DH flange's z axis or a point (3,) in the tip link's frame (mm)."""

    robot: str | None = None
    urdf: str | None = None
    tip: str | None = None
    base: str | None = None
    tool: object = None

    @property
    def chosen(self) -> bool:
        return self.robot is not None or self.urdf is not None


def arm_columns(
    mset: MeasurementSet, rows: np.ndarray, row_point: np.ndarray, n_points: int, model: ArmModel, limits: list
) -> ArmColumns | None:
    """`ArmColumns` for the paired rows `rows` (indices into the file) grouped by `row_point`, or None when the file
    has no joint columns of the model, or (a model not chosen) the UR5 does not describe them: then `limits` says so.
    Raises InputError for a bad model, bad joint columns, or a chosen model that does not describe the robot."""
    chain = robot_chain(model.robot, model.urdf, model.tip, model.base, model.tool)
    q = joint_values(mset, chain)
    if q is None:
        if model.urdf is not None:
            raise InputError(
                f"{mset.source}: no joint columns of {chain.name} ({', '.join(chain.columns)}): the kinematic test "
                "needs each row's joint values"
            )
        return None
    b = np.asarray(mset.robot, float)[rows]
    check = check_model(chain, q[rows], b)
    if not check.passed:
        if model.chosen:
            raise InputError(check.message(mset.source, chain))
        limits.append(
            f"the joint columns are not a UR5's (with this tool): its forward kinematics lies {check.rms_mm:.1f} mm RMS "
            "from the robot columns, so the arm's kinematic error was not tested; give the robot's model (--robot or "
            "--urdf, --tip) and its tool (--tool)"
        )
        return None
    jac = position_jacobian(chain, q[rows])  # (R, 3, P)
    cols = ArmColumns(
        _per_point(jac, row_point, n_points), jac, chain.name, chain.tip, tuple(chain.tool.tolist()), check
    )
    if chain.inertia is None:
        return cols
    loads = gravity_loads(chain, q[rows])
    terms = candidate_terms(chain, loads)
    if not terms:
        return cols
    _, jp, _ = chain.kinematics(q[rows])
    assert jp is not None
    scales = angle_scale(chain) * np.array([factor_scale(t, loads) for t in terms])
    jt = term_jacobian(terms, loads, jp) / scales
    return replace(
        cols, load_terms=terms, load_fields=_per_point(jt, row_point, n_points), load_row_fields=jt, load_scales=scales
    )


def _per_point(jac: np.ndarray, row_point: np.ndarray, n_points: int) -> np.ndarray:
    """(K, N, 3): the mean of the rows' columns (R, 3, K) over each point's rows."""
    mean = np.zeros((n_points, 3, jac.shape[2]))
    np.add.at(mean, row_point, jac)
    mean /= np.bincount(row_point, minlength=n_points)[:, None, None]
    return np.moveaxis(mean, 2, 0)


def judge_compliance(y, x_acc, kfull, load_cols, a_each: float, tests: dict, beside_field):
    """The `compliance` test (docs/theory.md §6.5): do the load terms' columns `load_cols` (3n, T) explain the
    residuals `y` beyond everything accepted `x_acc` AND the arm's geometric columns `kfull` (whether or not
    `kinematic` was accepted)? Nested F-test at a_each; when significant, judged again beside a smooth field of
    position (`beside_field(x0, x1)` → p) like the kinematic test. Returns (p, p beside the field, the usable
    columns (3n, j), their map (T, j), the F-test's q, nu, F, RSS before and after) or None when no direction of
    the load columns is left beside the geometric ones."""
    x0 = (x_acc, kfull)  # column blocks (`diagnosis_stats.fit`)
    # (built from joint values, not measured positions: like the kinematic columns, only directions inside the base
    # up to 1e-4 of their energy are left out)
    cols, _, c_map = usable(x0, load_cols, kept=1e-4)
    if cols.shape[1] == 0:
        return None
    p_c, q_c, nu_c, f_c, rss_a, rss_c, _ = ftest(y, x0, (x0, cols))
    tests["compliance"] = p_c
    p_cf = 1.0
    if p_c < a_each:
        p_cf = beside_field(x0, cols)
        tests["compliance_beside_field"] = p_cf
    return p_c, p_cf, cols, c_map, q_c, nu_c, f_c, rss_a, rss_c


#: a column name that looks like a joint value: q1, j_2, joint3, axis_4, a5, theta6, or any name with "joint"
JOINT_LIKE = re.compile(r"^(q|j|a|axis|joint|theta)[ _-]?\d+$|joint", re.IGNORECASE)
#: the largest scale error (ppm) we take a laser tracker, total station or CMM to have: their distance errors are a
#: few ppm of the range (docs/uncertainty.md, "Instruments"; docs/cli.md, `rrbc diagnose`)
INSTRUMENT_SCALE_PPM = 10.0


def joint_like_columns(mset: MeasurementSet) -> list[str]:
    """The file's extra columns whose names look like joint values (`JOINT_LIKE`)."""
    return [c for c in mset.extra if JOINT_LIKE.search(str(c).strip())]


def arm_untested_hint(
    mset: MeasurementSet, arm_tested: bool, effects: dict, instrument: str | None = None
) -> str | None:
    """A limit for a file with joint columns whose arm was not tested (no model given, or the default UR5 does not
    describe it): the sensor effects named may be the arm's, and how to give its model; with a named `scale`
    beyond `INSTRUMENT_SCALE_PPM`, that it is more than a measuring instrument's. None when nothing applies."""
    if arm_tested:
        return None
    cols = joint_like_columns(mset)
    if not cols:
        return None
    sensor = [n for n in ("scale", "affine", "smooth_field") if n in effects]
    text = (
        f"the file has joint columns ({', '.join(cols[:8])}{', ...' if len(cols) > 8 else ''}) but no arm model was "
        "tested: an arm's kinematic or load errors show in the sensor frame as a scale, an affine term or a smooth "
        "field"
    )
    if "kinematic" in effects:
        text += " (what follows the joint configuration itself is named kinematic, without its parameters)"
    if sensor:
        text += f", so what is named here ({', '.join(sensor)}) may be the arm's"
    if "scale" in effects and instrument is None:  # (with an instrument, `implausible_scale` says it)
        ppm = float(effects["scale"].parameters.get("ppm", 0.0))
        if abs(ppm) > INSTRUMENT_SCALE_PPM:
            text += (
                f"; a scale of {ppm:+.0f} ppm is more than a laser tracker, total station or CMM has (a few ppm), so "
                "unless the sensor is a camera the arm is the likelier cause"
            )
    return (
        text + "; give the arm's model (--robot ur5|ur10, or --urdf ROBOT.urdf --tip LINK) and its tool (--tool) "
        "to test it, and rrbc calibrate to correct it"
    )


#: a joint-like column whose name says it is a linear axis (a lift column, a rail): its value, not its angle
PRISMATIC_LIKE = re.compile(r"prism|lift|linear|slide|rail|track|gantry", re.IGNORECASE)
#: the model-free configuration test (`configuration_columns`): sums of up to this many consecutive angle columns
CONFIGURATION_CHAIN = 3
#: at least this many paired points per harmonic (each harmonic is 3 columns: one per robot axis)
CONFIGURATION_POINTS_PER_HARMONIC = 3
#: the model-free test's columns are never bigger than this many numbers (80 MB), whatever the file's size: the
#: harmonics without the products beyond it, and no test beyond that
CONFIGURATION_MAX_ELEMENTS = 10_000_000


def configuration_columns(
    mset: MeasurementSet, rows: np.ndarray, row_point: np.ndarray, n_points: int, limits: list
) -> ArmColumns | None:
    """Without an arm model, columns that let `rrbc diagnose` test whether the residuals follow the arm's joint
    configuration (docs/theory.md §6.5): the file's joint-like columns (`JOINT_LIKE`) as angles (radians, or degrees
    when a column goes beyond 2π) give sin and cos of each joint and of the sums of up to `CONFIGURATION_CHAIN`
    consecutive joints (a serial arm's error is built of such terms: parallel joints add their angles); a column
    beyond 400, or named like a linear axis (`PRISMATIC_LIKE`: a lift column, a rail), gives its value and
    its square. Each harmonic h(q) enters as three columns
    h(q)·e_a, one per robot axis: its fields (3H, N, 3). The products of the first angle's sin and cos with the
    others' (the base joint turning the rest of the arm) are added where the points allow
    (`CONFIGURATION_POINTS_PER_HARMONIC` per harmonic). None, with a limit saying why, when the file has no usable
    joint-like column or too few points even without the products."""
    names = joint_like_columns(mset)
    if not names:
        return None
    q = np.empty((len(rows), len(names)))
    for k, name in enumerate(names):
        try:
            q[:, k] = [float(v) for v in np.asarray(mset.extra[name], dtype=object)[rows]]
        except (TypeError, ValueError):
            limits.append(f"the joint-like column {name} is not numeric on every row: the configuration was not tested")
            return None
    if not np.all(np.isfinite(q)):
        limits.append("the joint-like columns have empty or non-finite values: the configuration was not tested")
        return None
    feats: list[np.ndarray] = []
    angles: list[np.ndarray] = []
    for k in range(len(names)):
        col = q[:, k]
        if np.ptp(col) <= 0:
            continue  # a joint that does not move
        big = float(np.max(np.abs(col)))
        if PRISMATIC_LIKE.search(names[k]) or big > 400.0:  # a linear axis: its value and its square
            z = (col - col.mean()) / np.std(col)
            feats += [z, z**2]
        elif big <= 2 * np.pi + 0.1:
            angles.append(col)
        else:
            angles.append(np.radians(col))
    rest: list[np.ndarray] = []
    for length in range(1, CONFIGURATION_CHAIN + 1):
        for start in range(1, len(angles) - length + 1):
            a = np.sum(angles[start : start + length], axis=0)
            rest += [np.sin(a), np.cos(a)]
    first = [np.sin(angles[0]), np.cos(angles[0])] if angles else []
    full = feats + first + rest + [f * r for f in first for r in rest]
    # fewer points than the products need: the harmonics without them (the base joint's turn of the rest not followed)
    smaller = feats + first + rest
    if not full:
        return None
    need = CONFIGURATION_POINTS_PER_HARMONIC * len(smaller)

    def fits(harmonics: list) -> bool:  # enough points, and columns of a bounded size
        return (
            n_points >= CONFIGURATION_POINTS_PER_HARMONIC * len(harmonics)
            and 3 * max(len(rows), n_points) * 3 * len(harmonics) <= CONFIGURATION_MAX_ELEMENTS
        )

    if not fits(smaller) and n_points >= need:
        limits.append(
            f"the file has joint columns ({', '.join(names[:8])}) but {len(rows):,} paired rows: testing whether the "
            "residuals follow the arm's configuration without its model was left out (its columns would pass "
            f"{CONFIGURATION_MAX_ELEMENTS:,} numbers); give the arm's model to test it"
        )
        return None
    h = np.array(full if fits(full) else smaller)  # (H, R)
    h = h - h.mean(axis=1, keepdims=True)  # the constant part is the rigid translation's
    if n_points < need:
        limits.append(
            f"the file has joint columns ({', '.join(names[:8])}) but only {n_points} paired points: testing whether "
            f"the residuals follow the arm's configuration without its model needs {need} ({len(h)} harmonics of the "
            "joint values); give the arm's model to test it with fewer"
        )
        return None
    row_fields = np.zeros((len(rows), 3, 3 * len(h)))
    for a in range(3):
        row_fields[:, a, a::3] = h.T
    return ArmColumns(
        _per_point(row_fields, row_point, n_points),
        row_fields,
        "",
        "",
        (),
        None,
        model_free=tuple(names),
    )


def implausible_scale(effects: dict, instrument: str | None, has_joints: bool) -> str | None:
    """A limit when the named `scale` is more than the given instrument plausibly has
    (`models.instrument.PLAUSIBLE_SCALE_PPM`): the cause is then likelier elsewhere (the arm, when the file has
    joint columns; the two frames' units or a thermal state otherwise). None when nothing applies."""
    from rrbc_core.models.instrument import PLAUSIBLE_SCALE_PPM

    if instrument is None or "scale" not in effects:
        return None
    ppm = float(effects["scale"].parameters.get("ppm", 0.0))
    limit = PLAUSIBLE_SCALE_PPM[instrument]
    if abs(ppm) <= limit:
        return None
    cause = (
        "the arm (its lengths, or its kinematic error seen as a scale) is the likelier cause"
        if has_joints
        else "look for another cause: the robot's own scale (its lengths), a unit or a temperature left uncompensated"
    )
    return (
        f"the scale of {ppm:+.4g} ppm is more than a {instrument} plausibly has (at most {limit:g} ppm, "
        f"docs/limits.md): {cause}"
    )


def short_field(effects: dict, points: np.ndarray, spacing: float | None = None) -> str | None:
    """A limit when the named smooth field's correlation length is shorter than the points' typical spacing (the
    median distance to the nearest other point; `spacing` when the caller has it, `diagnosis_moran.neighbours`):
    neighbouring points do not share such a 'field', and no sensor distorts its space that way. None when nothing
    applies."""
    if "smooth_field" not in effects or len(points) < 3:
        return None
    length = float(effects["smooth_field"].parameters.get("length_scale_mm", np.inf))
    if spacing is None:
        from scipy.spatial import cKDTree

        spacing = float(np.median(cKDTree(points).query(points, k=2)[0][:, 1]))
    if not length < 0.5 * spacing:
        return None
    return (
        f"the smooth field's correlation length ({length:.3g} mm) is shorter than half the points' typical spacing "
        f"({spacing:.3g} mm): neighbouring points do not share it, so it is no sensor's smooth distortion; an error "
        "that changes from pose to pose (the arm's configuration, a loose tool) or noise beyond the model is likelier"
    )
