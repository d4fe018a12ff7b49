"""What the per-point bounds (`correction.bounds`) are computed from besides the cross-validation: a row's noise
estimated from the data when no instrument is given (`estimate_noise`), the instrument with every figure filled in
(`complete_instrument`), and the correction field's rate of change for points off coplanar fiducials
(`field_slope`), and how far the fiducials' cross-validation tests a prediction (`fold_distances`,
`tested_distance`). docs/uncertainty.md derives them. Units mm; frames as in the measurement file.
"""

from __future__ import annotations

import functools
from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree
from scipy.special import chdtri, fdtri  # the quantiles scipy.stats.chi2 / f give, without its import

from rrbc_core.interpolation.auto import folds_of
from rrbc_core.models.instrument import Instrument

#: fewer fiducials than this: no cross-validation, so no RRBC bound (a warning says so)
MIN_FIDUCIALS = 6
#: a point is bounded up to this percentile of the folds' held-out distances (`tested_from`)
TESTED_PERCENTILE = 90


def fit_quadratic(d2: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Non-negative (a, b) of y ≈ a + b·d2, least squares weighted by 1/d2² (y's spread grows as d2: the closest
    pairs say most about a), i.e. y/d2 ≈ a/d2 + b. d2 > 0."""
    from scipy.optimize import nnls  # here, not at import: scipy.optimize is most of a command's start-up

    d2 = np.maximum(d2, 1e-12)
    scale = float(np.median(d2))
    (a, b), _ = nnls(np.column_stack([scale / d2, np.ones_like(d2)]), y / d2 * scale)
    return float(a), float(b) / scale


def estimate_noise(
    data, rotation: np.ndarray, fid_sensor: np.ndarray, fid_corr: np.ndarray
) -> tuple[float, str] | None:
    """The per-axis variance of one row's readings, sensor's and robot's together in the robot frame (mm²), and
    where it came from; None when the data hold no estimate.

    From repeats (ids read more than once among the rows with robot readings: the spread of each id's T-free
    difference R s − b about its mean, pooled) when there are at least 3 degrees of freedom; else from the fiducials'
    nearest-neighbour differences of their corrections, |R(c_i − c_j)|² ≈ 2·3σ² + B d² (the intercept at d = 0),
    when their distances spread over at least a factor 2; else (a grid's do not: no intercept can be read) the
    closest quarter of those pairs' mean |R(c_i − c_j)|² / 6, an upper bound (the field's own change is in it). None
    with fewer than 3 fiducials and no repeats.
    """
    if data is not None and len(set(data.ids)) < len(data.ids):  # some id read more than once
        rows = np.flatnonzero(np.isfinite(data.robot).all(axis=1))
        ids = [data.ids[i] for i in rows]
        index: dict = {}
        inv = np.fromiter((index.setdefault(i, len(index)) for i in ids), int, len(ids))  # each row's id, numbered
        counts = np.bincount(inv, minlength=len(index)) if len(ids) else np.zeros(0, int)
        dof = int(np.sum(counts - 1))
        if dof >= 3:
            diff = data.sensor[rows] @ np.asarray(rotation).T - data.robot[rows]
            mean = np.zeros((len(index), 3))
            np.add.at(mean, inv, diff)
            mean /= counts[:, None]
            ss = float(np.sum((diff - mean[inv]) ** 2))
            return ss / (3 * dof), f"estimated from repeated readings ({dof} degrees of freedom)"
    n = len(fid_sensor)
    if n < 3:
        return None
    dist, j = cKDTree(fid_sensor).query(fid_sensor, k=2)
    ii, jj = np.unique(np.sort(np.c_[np.arange(n), j[:, 1]], axis=1), axis=0).T  # each nearest pair once
    d2 = np.sum((fid_sensor[ii] - fid_sensor[jj]) ** 2, axis=1)
    y = np.sum((fid_corr[ii] - fid_corr[jj]) ** 2, axis=1)
    close = d2 <= np.percentile(d2, 25)  # the closest quarter of the pairs bounds the noise above
    if n >= MIN_FIDUCIALS and np.max(d2) >= 4 * max(float(np.min(d2)), 1e-12):
        a, _ = fit_quadratic(d2[d2 > 0], y[d2 > 0]) if np.any(d2 > 0) else (float(np.mean(y)), 0.0)
        a = min(a, float(np.mean(y[close])))
        return a / 6.0, f"estimated from the fiducials' nearest-neighbour differences ({len(ii)} pairs)"
    # a grid (one spacing: no intercept to read) or few fiducials
    return (
        float(np.mean(y[close])) / 6.0,
        f"not estimable (no repeats; the fiducials' spacing too even to read): the most the closest "
        f"{int(close.sum())} fiducial pairs' differences allow, an upper bound",
    )


def field_slope(fid_sensor: np.ndarray, fid_corr_robot: np.ndarray, noise_mm2: float) -> float:
    """g² (mm²/mm²): the mean squared rate of change of the correction field, from the fiducials' nearest-neighbour
    pairs, mean of (|c_i − c_j|² − 2ν)/d², clipped at 0 (ν a fiducial's own 3-D noise variance). What a point off
    coplanar (or collinear) fiducials is taken to see over its height h: variance g² h²."""
    n = len(fid_sensor)
    if n < 2:
        return 0.0
    dist, j = cKDTree(fid_sensor).query(fid_sensor, k=2)
    d = dist[:, 1]
    ok = d > 1e-9
    if not np.any(ok):
        return 0.0
    y = np.sum((fid_corr_robot - fid_corr_robot[j[:, 1]]) ** 2, axis=1)
    return max(float(np.mean((y[ok] - 2 * noise_mm2) / d[ok] ** 2)), 0.0)


def complete_instrument(
    inst: Instrument | None, estimate: tuple[float, str] | None, sensor_var_at_fid: float
) -> Instrument:
    """The instrument with every figure filled in: without one, the estimate is the sensor's per-axis σ (the robot's
    included); with one whose robot noise is unknown, the robot's is what the estimate leaves beyond the sensor's
    (0 without an estimate)."""
    if inst is None or inst.name == "estimated":
        robot = None if inst is None else inst.robot_mm
        if estimate is None:
            return Instrument(
                name="estimated",
                robot_mm=robot,
                source="not estimable (no repeats, too few fiducials): taken as 0",
                robot_source="given (--robot-noise-mm)" if robot is not None else "included in the sensor's figure",
            )
        var, why = estimate
        if robot is not None:
            return Instrument(
                name="estimated",
                sigma_mm=float(np.sqrt(max(var - robot**2, 0.0))),
                robot_mm=robot,
                source=f"{why}, less the robot's given noise",
                robot_source="given (--robot-noise-mm)",
            )
        return Instrument(
            name="estimated",
            sigma_mm=float(np.sqrt(var)),
            source=why + " (the sensor's and the robot's noise together)",
            robot_source="included in the sensor's figure",
        )
    if inst.robot_mm is not None or inst.covariances is not None:
        return inst
    if estimate is None:
        return replace(inst, robot_mm=0.0, robot_source="not estimable (no repeats, too few fiducials): taken as 0")
    var, why = estimate
    robot = float(np.sqrt(max(var - sensor_var_at_fid, 0.0)))
    return replace(inst, robot_mm=robot, robot_source=f"{why}, less the instrument's noise")


def fold_distances(fid_sensor: np.ndarray) -> np.ndarray:
    """(F,): each fiducial's distance (sensor frame, mm) from the nearest fiducial outside its fold
    (`interpolation.auto.folds_of`): how far the cross-validation predicts it from."""
    n = len(fid_sensor)
    fold = folds_of(n)
    dist = np.full(n, np.inf)
    if n < 2 or fold.max() == 0:
        return dist
    # one tree: each point's nearest neighbours, the first in another fold (folds are dealt at random, so one is
    # almost always among the nearest 6); per fold, with the rest's own tree, for the few that have none there
    d, j = cKDTree(fid_sensor).query(fid_sensor, k=min(n, 6))
    other = fold[j] != fold[:, None]
    found = other.any(axis=1)
    dist[found] = d[found, np.argmax(other[found], axis=1)]
    for f in np.unique(fold[~found]):
        test = (fold == f) & ~found
        dist[test] = cKDTree(fid_sensor[fold != f]).query(fid_sensor[test])[0]
    return dist


def tested_distance(fid_sensor: np.ndarray, distances: np.ndarray | None = None) -> float | None:
    """The distance (mm) up to which the fiducials' cross-validation tests a prediction: the 90th percentile of
    `fold_distances` (given as `distances` when already computed); None with fewer than 3 fiducials (nothing
    tested, no limit applied)."""
    if len(fid_sensor) < 3:
        return None
    return tested_from(fold_distances(fid_sensor) if distances is None else distances)


def tested_from(distances: np.ndarray) -> float:
    """The distance the folds tested (mm): the `TESTED_PERCENTILE`th percentile of the held-out points' distances
    from the nearest fiducial left in (the finite ones; 0 without any)."""
    d = np.asarray(distances, float)
    d = d[np.isfinite(d)]
    return float(np.percentile(d, TESTED_PERCENTILE)) if len(d) else 0.0


@functools.cache
def predictive_factor(dof: int, level: float = 0.95) -> float:
    """How much wider a `level` bound on a new point's 3-D error must be when its variance is estimated with `dof`
    degrees of freedom rather than known: sqrt(3 F_level(3, dof) / chi²_level(3)) (the new error's squared length
    over the estimate is 3 F(3, dof) for a normal error; docs/uncertainty.md). 1 as dof grows. Cached: a drag's
    bounds ask for it with the same few dof again and again."""
    return float(np.sqrt(3.0 * fdtri(3.0, float(max(int(dof), 1)), level) / chdtri(3.0, 1.0 - level)))
