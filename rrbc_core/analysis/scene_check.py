"""Hold a scene's error model against a measured file: predict, compare, name, extend, score (`rrbc check-model`;
docs/check_model.md).

- **predict** (`scene_prediction`): the scene's error model simulated at the file's own points, `trials` times;
  the FRE and the rigid and RRBC check RMS with 95 % intervals, and each row's rigid residual as a mean (3,) and a
  covariance (3, 3) over the trials.
- **compare**: a summary figure outside its interval is a misfit; a row is outside its own 95 % region when its
  measured residual's Mahalanobis distance z from the predicted mean (predicted covariance plus 1e-9 mm² on the
  diagonal) exceeds √χ²₃(0.95) = 2.80; how many rows a file of the model has outside is read from the trials
  themselves (rows share their station's registration: the count varies far more than a binomial). What the misfit follows is read from what is unexplained (position: scale,
  affine, smooth field; time: drift; joint configuration: kinematic, compliance) and, with stations, from a χ² test
  of each station's sum of z² (3 per row) at alpha over the stations.
- **name**: the remainder (each row's measured residual less its predicted mean, placed at its mapped point in the
  robot frame, one frame for all stations) is given to `diagnose` (the same tests and sizes); an effect the model
  already has a term for (anisotropic noise, outliers) is not repeated. The noise is compared too: when the
  remainder's noise variance (diagnose's estimate) exceeds the model's (the mean predicted residual variance per
  axis) by more than an F/χ² test at alpha allows, `isotropic_noise` is named with the missing part.
- **extend** (`scene_extension`): the named effects written as robot-side error terms; then the extended model is
  simulated at the rows, and the scatter they still show about it beyond its predicted covariance (a χ² test at
  alpha) is written as `isotropic_noise` (`scene_extension.spread_effect`), in the file's extension and in each fold's.
- **score**: K folds (the stations when the file has at least two, else the paired ids shuffled by `seed`); for
  each fold the naming and extending are repeated on the other folds' rows alone, and the extended model predicts
  the held-out rows: the RMS over held-out rows of |measured − predicted mean residual| and the share of held-out
  rows inside their 95 % region, before (the scene as given) and after.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from rrbc_core.analysis.diagnosis import Diagnosis, Effect, diagnose
from rrbc_core.analysis.diagnosis_stats import TIME_FOLLOWS_POSITION
from rrbc_core.analysis.scene_extension import AddedTerm, extension_terms, spread_effect, with_spread
from rrbc_core.analysis.scene_prediction import (
    Figures,
    Interval,
    at_physical_points,
    file_stations,
    measured_figures,
    predict,
)
from rrbc_core.errors import InputError
from rrbc_core.io.id_sets import member_of
from rrbc_core.io.measurements import MeasurementSet
from rrbc_core.models.errormodels import ErrorModel
from rrbc_core.runtime.threads import thread_limited

__all__ = ["PointMisfit", "SceneCheck", "check_scene_model", "outside_counts"]

Z95 = float(np.sqrt(stats.chi2.ppf(0.95, 3)))  # a row's 95 % region: z <= Z95
_JITTER = 1e-9  # mm², added to each predicted covariance's diagonal (a noise-free model's rows)
FOLLOWS = {
    "scale": "position",
    "affine": "position",
    "smooth_field": "position",
    "drift": "time",
    "kinematic": "joint configuration",
    "compliance": "joint configuration",
    "outliers": "single points",
    "isotropic_noise": "noise",
    "anisotropic_noise": "noise",
}
_HAS = {"anisotropic_noise": ("anisotropic_noise", "range_noise"), "outliers": ("outliers",)}


@dataclass(frozen=True)
class PointMisfit:
    """A row outside its predicted 95 % region: its id (and station), z, and |measured − predicted mean| (mm)."""

    id: str
    z: float
    miss_mm: float
    group: str = ""

    def to_json(self) -> dict:
        out = {"id": self.id, "z": self.z, "miss_mm": self.miss_mm}
        if self.group:
            out["group"] = self.group
        return out


@dataclass(frozen=True, eq=False)
class SceneCheck:
    """The outcome of `check_scene_model`; `to_json()` is the JSON of `rrbc check-model --json` (docs/cli.md)."""

    predicted: dict  # name -> Interval (None when the file has no such figure)
    measured: dict  # name -> float or None
    outside: tuple[PointMisfit, ...]
    n_rows: int  # rows with a robot value (the ones compared)
    outside_by_chance: Interval  # how many rows a file of the model has outside, over the trials
    unexplained: tuple[Effect, ...]
    follows: tuple[str, ...]
    stations_off: tuple[str, ...]
    added: tuple[AddedTerm, ...]
    not_written: tuple[str, ...]
    gain: dict
    trials: int
    alpha: float
    limits: tuple[str, ...] = ()
    extended_model: ErrorModel | None = field(default=None, repr=False)
    #: per row with both readings (file order): its index in the file, its id, its mapped reading (robot frame, mm),
    #: measured minus predicted mean residual (mm) and z; what the app draws
    rows: np.ndarray = field(default_factory=lambda: np.zeros(0, int), repr=False)
    row_ids: tuple[str, ...] = ()
    points_mm: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)), repr=False)
    misfit_mm: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)), repr=False)
    z: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)

    @property
    def figures_outside(self) -> tuple[str, ...]:
        return tuple(
            k
            for k, iv in self.predicted.items()
            if iv is not None and self.measured.get(k) is not None and not iv.contains(self.measured[k])
        )

    def figure_rows(self) -> list[tuple[str, float | None, Interval | None, bool]]:
        """(label, measured, predicted interval, outside it) for the FRE and the rigid and RRBC check RMS: what the
        command's table and the app's show (None where the file has no such rows)."""
        outside = set(self.figures_outside)
        labels = (("fre_mm", "FRE"), ("rmst_rigid_mm", "rigid RMST"), ("rmst_rrbc_mm", "RRBC RMST"))
        return [(label, self.measured[k], self.predicted[k], k in outside) for k, label in labels]

    @property
    def model_fits(self) -> bool:
        """Every figure inside its interval, no more rows outside than the model's files show (95 %), nothing
        unexplained."""
        return not self.figures_outside and not self.unexplained and len(self.outside) <= self.outside_by_chance.hi95

    def to_json(self) -> dict:
        return {
            "predicted": {k: None if v is None else v.to_json() for k, v in self.predicted.items()},
            "measured": dict(self.measured),
            "figures_outside": list(self.figures_outside),
            "outside": [p.to_json() for p in self.outside],
            "rows_compared": self.n_rows,
            "outside_by_chance": self.outside_by_chance.to_json(),
            "misfit_follows": list(self.follows),
            "stations_off": list(self.stations_off),
            "unexplained": [e.to_json() for e in self.unexplained],
            "extended_terms": [t.table for t in self.added],
            "not_written": list(self.not_written),
            "gain": dict(self.gain),
            "model_fits": self.model_fits,
            "trials": self.trials,
            "alpha": self.alpha,
            "limits": list(self.limits),
        }


def _moments(fig: Figures) -> tuple[np.ndarray, np.ndarray]:
    """Per-row mean (R, 3) and covariance (R, 3, 3) of the trials' residuals."""
    res = fig.residual
    mean = np.mean(res, axis=0)
    dev = res - mean
    cov = np.einsum("tri,trj->rij", dev, dev) / max(len(res) - 1, 1)
    return mean, cov + _JITTER * np.eye(3)


def _z(measured: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Mahalanobis distance (R,) of measured residuals from the predicted ones; NaN rows stay NaN."""
    d = measured - mean
    ok = np.all(np.isfinite(d), axis=1)
    z = np.full(len(d), np.nan)
    if ok.any():
        sol = np.linalg.solve(cov[ok], d[ok][..., None])[..., 0]
        z[ok] = np.sqrt(np.maximum(np.sum(d[ok] * sol, axis=1), 0.0))
    return z


def _levelling(cov: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Seeded noise (R, 3) that brings each row's predicted residual covariance up to v·I, v the 90th percentile of
    the rows' largest eigenvalues (rows above keep their own): diagnose's tests assume one noise level, and a file's
    check rows (truth as robot value) are less noisy than its measured rows. Zero-mean: systematic parts unchanged."""
    ev, vec = np.linalg.eigh(cov)
    level = float(np.quantile(ev[:, -1], 0.9))
    add = np.clip(level - ev, 0.0, None)  # (R, 3) the missing variance along each eigenvector
    z = rng.standard_normal(ev.shape) * np.sqrt(add)
    return np.einsum("rij,rj->ri", vec, z)


def outside_counts(pred: Figures, mean: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """(T,) how many rows of each trial fall outside their own 95 % region: the count a file of the model shows by
    chance. Rows share their station's registration, so the count varies far more than a binomial's."""
    d = pred.residual - mean[None]
    ok = np.all(np.isfinite(d[0]), axis=1)
    inv = np.linalg.inv(cov[ok])
    z2 = np.einsum("tri,rij,trj->tr", d[:, ok], inv, d[:, ok])
    return np.sum(z2 > Z95**2, axis=1).astype(float)


def _remainder(
    mset: MeasurementSet, meas: Figures, mean: np.ndarray, cov: np.ndarray, rows: np.ndarray, seed: int
) -> MeasurementSet:
    """The rows `rows` (with robot values) as a file in one frame: sensor := the mapped reading (robot frame), robot
    := mapped + (measured residual − predicted mean) + levelling noise (`_levelling`). No group column: every
    station is in the robot frame."""
    from rrbc_core.io.groups import GROUP_COLUMN

    mapped = meas.mapped[0][rows]
    level = _levelling(cov[rows], np.random.default_rng([int(seed) & 0x7FFFFFFF, 36]))
    robot = mapped + (meas.residual[0][rows] - mean[rows]) + level
    roles = tuple("check" if mset.roles[i] == "check" else "both" for i in rows)
    extra = {k: tuple(v[i] for i in rows) for k, v in mset.extra.items() if k != GROUP_COLUMN}
    ids = tuple(
        mset.ids[i] if GROUP_COLUMN not in mset.extra else f"{mset.extra[GROUP_COLUMN][i]}:{mset.ids[i]}" for i in rows
    )
    return MeasurementSet(
        ids=ids,
        roles=roles,
        sensor=mapped,
        robot=robot,
        time=np.asarray(mset.time, float)[rows],
        lines=tuple(mset.lines[i] for i in rows),
        source=mset.source,
        extra=extra,
    )


def _levelled_var(cov: np.ndarray, rows: np.ndarray) -> float:
    """The remainder's noise variance per axis (mm²) that the model predicts for rows `rows`, after `_levelling`."""
    ev = np.linalg.eigvalsh(cov[rows])
    return float(np.mean(np.maximum(ev, np.quantile(ev[:, -1], 0.9))))


def _noise_effect(diag: Diagnosis, cov: np.ndarray, rows: np.ndarray, alpha: float) -> Effect | None:
    """`isotropic_noise` when the remainder's noise exceeds the model's (module docstring)."""
    s2 = float(np.mean(np.square(diag.noise_sigma_mm)))
    pred = _levelled_var(cov, rows)
    nu = max(3 * len(rows) - 6, 1)
    if s2 <= pred:
        return None
    p = float(stats.chi2.sf(nu * s2 / max(pred, 1e-300), nu))
    if p >= alpha:
        return None
    extra = float(np.sqrt(s2 - pred))
    return Effect(
        "isotropic_noise",
        {"sigma_mm": extra},
        p,
        f"the noise beside the named effects ({np.sqrt(s2):.3g} mm per axis, from {diag.noise_source}) is larger than "
        f"the model's ({np.sqrt(pred):.3g} mm, the predicted residual spread; χ²({nu}) p {p:.2g}); "
        f"sigma_mm is the missing part, √(measured² − predicted²).",
        magnitude_mm=extra * np.sqrt(3.0),
    )


def _name(
    mset: MeasurementSet,
    meas: Figures,
    mean: np.ndarray,
    cov: np.ndarray,
    rows: np.ndarray,
    model: ErrorModel,
    alpha: float,
    seed: int,
    arm: dict,
) -> tuple[list[Effect], MeasurementSet, Diagnosis]:
    """What the model leaves unexplained in rows `rows`, in diagnose's vocabulary (module docstring)."""
    rem = _remainder(mset, meas, mean, cov, rows, seed)
    diag = diagnose(rem, alpha=alpha, seed=seed, configuration=False, **arm)  # a scene's arm is its model
    kinds = set(model.kinds)
    effects = [e for e in diag.effects if not any(k in kinds for k in _HAS.get(e.name, ()))]
    noise = _noise_effect(diag, cov, rows, alpha)
    if noise is not None:
        effects.append(noise)
    return effects, rem, diag


def _not_at_points(scene, mset: MeasurementSet, exc: InputError) -> str:
    """Why the scene's model cannot be simulated at the file's points, naming both."""
    name = getattr(scene, "path", None) or getattr(scene, "name", "the scene")
    detail = " ".join(str(exc).split())
    return (
        f"{name}: its error model cannot be evaluated at the points of {mset.source}: is this the scene of the cell "
        f"those data were measured in? ({detail[:300]}{'…' if len(detail) > 300 else ''})"
    )


def _file_arm(mset: MeasurementSet, scene, robot: str):
    """The scene's arm (its spec for `armterms.arm_chain`) and the file's joint values for it (R, I), or (spec or
    None, None) when the scene has no arm or the file none of its columns."""
    from rrbc_core.io.joints import joint_values
    from rrbc_core.models.armterms import arm_chain

    urdf = "" if scene.robot_urdf is None else str(scene.robot_urdf)
    if not urdf and robot == "none":
        return None, None
    spec = {"urdf": urdf, "tip": scene.robot_tip or "", "robot": "" if urdf else robot}
    spec["tool_mm"] = (0.0, 0.0, float(scene.tool_mm))
    return spec, joint_values(mset, arm_chain(**spec))


def _arm(mset: MeasurementSet, scene, robot: str, q) -> dict:
    """diagnose's arm model for the scene's robot when the file has its joint columns (`q`, from `_file_arm`): a
    UR5/UR10 (q1..q6) or the scene's URDF (columns named after its joints); {} otherwise."""
    if robot != "none":
        return {"robot": robot, "tool_mm": scene.tool_mm} if "q1" in mset.extra else {}
    if scene.robot_urdf is None or q is None:
        return {}
    return {"urdf": scene.robot_urdf, "tip": scene.robot_tip, "tool_mm": (0.0, 0.0, scene.tool_mm)}


def _time_on_position(rem: MeasurementSet) -> float:
    """R² of the rows' times on their positions (`diagnosis_stats.time_on_position`: the one rule)."""
    from rrbc_core.analysis.diagnosis_stats import time_on_position

    return time_on_position(np.asarray(rem.sensor, float), np.asarray(rem.time, float))


def _folds(mset: MeasurementSet, paired: np.ndarray, k: int, seed: int) -> tuple[list[np.ndarray], str]:
    """Held-out row sets: stations round-robin when there are at least two, else paired ids shuffled."""
    from rrbc_core.io.groups import GROUP_COLUMN, has_groups

    if has_groups(mset):
        g = np.asarray(mset.extra[GROUP_COLUMN], dtype=object)
        names = list(dict.fromkeys(g[paired].tolist()))
        if len(names) >= 2:
            k = min(k, len(names))
            return [paired[member_of(g[paired], names[j::k])] for j in range(k)], "station"
    ids = np.asarray(mset.ids, dtype=object)
    uniq = np.array(list(dict.fromkeys(ids[paired].tolist())), dtype=object)
    np.random.default_rng(seed).shuffle(uniq)
    k = min(k, len(uniq))
    return [paired[member_of(ids[paired], uniq[j::k])] for j in range(k)], "point"


@thread_limited
def check_scene_model(
    mset: MeasurementSet,
    scene,
    trials: int = 200,
    folds: int = 5,
    seed: int = 0,
    alpha: float = 0.01,
) -> SceneCheck:
    """Hold a scene's error model against a measured file (module docstring).

    Parameters
    ----------
    mset : MeasurementSet
        The measured file: registration rows (at least 3 per station), fiducial, check and target rows, optional
        time, group and q1..q6 columns.
    scene : Scene
        A loaded scene (`io.scene_toml.load_scene`): its error model, robot model and tool yaw.
    trials : int
        Monte Carlo trials of the model's random terms (at least 20).
    folds : int
        K of the out-of-sample score (at least 2).
    seed : int
        Seed of the trials, the folds and diagnose's bootstraps.
    alpha : float
        False-alarm rate of the naming (diagnose's family-wise alpha) and of the noise and station tests.

    Returns
    -------
    SceneCheck
        Predicted intervals, measured figures, rows outside their region, what is unexplained, the terms that
        extend the model, and the out-of-sample gain.

    Raises
    ------
    InputError
        Too few trials or folds, alpha out of range, a station with fewer than 3 registration rows, fewer than 5
        paired points, or work beyond the simulation's bound (`scene_prediction.MAX_WORK`).
    """
    if int(trials) < 20:
        raise InputError(f"--trials must be at least 20 (the 95 % intervals are quantiles of the trials), got {trials}")
    if int(folds) < 2:
        raise InputError(f"--folds must be at least 2, got {folds}")
    if not 0 < float(alpha) < 1:
        raise InputError(f"alpha must be between 0 and 1, got {alpha!r}")
    trials, folds = int(trials), int(folds)
    model: ErrorModel = scene.error_model
    robot = scene.robot_model if scene.robot_model in ("ur5", "ur10") else "none"
    spec, q = _file_arm(mset, scene, robot)
    stations = file_stations(mset, robot, scene.tool_yaw_deg, q)
    try:
        stations = at_physical_points(mset, stations, model)
    except InputError as exc:
        raise InputError(_not_at_points(scene, mset, exc)) from None
    arm = _arm(mset, scene, robot, q)
    meas = measured_figures(mset, stations)
    try:
        pred = predict(mset, stations, model, trials, seed)
    except InputError as exc:
        if "--trials" in str(exc):
            raise
        raise InputError(_not_at_points(scene, mset, exc)) from None
    mean, cov = _moments(pred)
    z = _z(meas.residual[0], mean, cov)
    paired = np.flatnonzero(np.isfinite(z))
    by_chance = Interval.of(outside_counts(pred, mean, cov))
    if len(paired) < 5:
        raise InputError(f"{mset.source}: {len(paired)} rows with both readings; check-model needs at least 5")

    predicted = {
        "rmst_rigid_mm": None if pred.rmst_rigid is None else Interval.of(pred.rmst_rigid),
        "rmst_rrbc_mm": None if pred.rmst_rrbc is None else Interval.of(pred.rmst_rrbc),
        "fre_mm": Interval.of(pred.fre),
    }
    measured = {
        "rmst_rigid_mm": None if meas.rmst_rigid is None else float(meas.rmst_rigid[0]),
        "rmst_rrbc_mm": None if meas.rmst_rrbc is None else float(meas.rmst_rrbc[0]),
        "fre_mm": float(meas.fre[0]),
    }
    from rrbc_core.io.groups import GROUP_COLUMN

    groups = mset.extra.get(GROUP_COLUMN)
    miss = np.linalg.norm(meas.residual[0] - mean, axis=1)
    out_rows = sorted((i for i in paired if z[i] > Z95), key=lambda i: -z[i])
    outside = tuple(
        PointMisfit(mset.ids[i], float(z[i]), float(miss[i]), "" if groups is None else str(groups[i]))
        for i in out_rows
    )
    stations_off = []
    if len(stations) > 1:
        for st in stations:
            zz = z[st.rows][np.isfinite(z[st.rows])]
            if len(zz) and stats.chi2.sf(float(np.sum(zz**2)), 3 * len(zz)) < alpha / len(stations):
                stations_off.append(st.name)

    effects, rem, _ = _name(mset, meas, mean, cov, paired, model, alpha, seed, arm)
    added, not_written = extension_terms(effects, rem, None if q is None else (spec, q[paired]))
    if added:
        added, _, spread = _spread(mset, stations, meas, model, added, paired, trials, seed + 999, alpha)
        if spread is not None:  # one isotropic_noise, sized as the term written (`with_spread`: in quadrature)
            before = [e for e in effects if e.name == "isotropic_noise"]
            if before:
                sigma = float(np.hypot(before[0].parameters["sigma_mm"], spread.parameters["sigma_mm"]))
                spread = Effect(
                    "isotropic_noise",
                    {"sigma_mm": sigma},
                    min(before[0].p_value, spread.p_value),
                    f"{before[0].evidence} Beside the extension: {spread.evidence} In all {sigma:.3g} mm per axis.",
                    magnitude_mm=sigma * np.sqrt(3.0),
                )
            effects = [e for e in effects if e.name != "isotropic_noise"] + [spread]
    extended = model.extended(robot=[t.term for t in added])
    follows = list(dict.fromkeys(FOLLOWS[e.name] for e in effects if e.name in FOLLOWS))
    if stations_off:
        follows.append("station")

    joints = None if q is None else (spec, q)
    gain = _score(
        mset, stations, meas, model, mean, cov, z, paired, trials, folds, seed, alpha, arm, joints, bool(added)
    )
    limits = []
    r2 = _time_on_position(rem)
    if r2 > TIME_FOLLOWS_POSITION and {"drift", "scale", "affine"} & {e.name for e in effects}:
        limits.append(
            f"time follows position in this file ({r2:.2f} of the time's variance is a linear function of position): "
            "a drift cannot be told from a linear map of position, so how drift, scale and affine share the misfit "
            "is not identified (their sum is; measure in another order to separate them)"
        )
    if "q1" in mset.extra and not arm:
        limits.append(
            "the file has q1..q6 columns but the scene's robot is neither a UR5/UR10 nor a URDF with those joints: "
            "the arm's error was not tested"
        )
    return SceneCheck(
        predicted,
        measured,
        outside,
        len(paired),
        by_chance,
        tuple(effects),
        tuple(follows),
        tuple(stations_off),
        tuple(added),
        tuple(not_written),
        gain,
        trials,
        float(alpha),
        tuple(limits),
        extended,
        paired,
        tuple(mset.ids[i] for i in paired),
        meas.mapped[0][paired],
        meas.residual[0][paired] - mean[paired],
        z[paired],
    )


def _spread(mset, stations, meas, model, terms, rows, trials, seed, alpha):
    """`terms` with the missing spread of rows `rows` about the extended model (`scene_extension.with_spread`);
    the moments of the model the terms make, and the spread effect or None."""
    moments = _moments(predict(mset, stations, model.extended(robot=[t.term for t in terms]), trials, seed))
    effect = spread_effect(meas.residual[0][rows] - moments[0][rows], moments[1][rows], alpha)
    if effect is None:
        return terms, moments, None
    terms = with_spread(terms, effect)
    moments = _moments(predict(mset, stations, model.extended(robot=[t.term for t in terms]), trials, seed))
    return terms, moments, effect


def _score(mset, stations, meas, model, mean, cov, z, paired, trials, folds, seed, alpha, arm, joints, extend) -> dict:
    """The out-of-sample score (module docstring)."""
    held, by = _folds(mset, paired, folds, seed)
    miss = np.linalg.norm(meas.residual[0] - mean, axis=1)
    before_err, after_err, before_in, after_in = [], [], [], []
    for k, test in enumerate(held):
        train = np.setdiff1d(paired, test)
        before_err.append(miss[test])
        before_in.append(z[test] <= Z95)
        terms: list = []
        if extend and len(np.unique(np.asarray(mset.ids, dtype=object)[train])) >= 5:
            effects, rem, _ = _name(mset, meas, mean, cov, train, model, alpha, seed + k + 1, arm)
            terms, _ = extension_terms(effects, rem, None if joints is None else (joints[0], joints[1][train]))
        if not terms:
            after_err.append(miss[test])
            after_in.append(z[test] <= Z95)
            continue
        terms, (m2, c2), _ = _spread(mset, stations, meas, model, terms, train, trials, seed + 1000 + k, alpha)
        after_err.append(np.linalg.norm(meas.residual[0][test] - m2[test], axis=1))
        after_in.append(_z(meas.residual[0], m2, c2)[test] <= Z95)
    cat = np.concatenate
    return {
        "prediction_error_before_mm": float(np.sqrt(np.mean(cat(before_err) ** 2))),
        "prediction_error_after_mm": float(np.sqrt(np.mean(cat(after_err) ** 2))),
        "coverage_before": float(np.mean(cat(before_in))),
        "coverage_after": float(np.mean(cat(after_in))),
        "folds": len(held),
        "fold_by": by,
    }
