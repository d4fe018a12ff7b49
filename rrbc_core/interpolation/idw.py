"""Inverse distance weighting (`IDW`, the published rule: the k nearest fiducials by 3-D distance in the sensor
frame, weights 1/d^p) and the zero baseline (`NoCorrection`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from rrbc_core.interpolation.base import (
    EXACT_MM,
    Fitted,
    FittedInterpolator,
    Hull,
    check_data,
    check_float,
    check_positive_int,
)
from rrbc_core.option_specs import check_options, option
from rrbc_core.runtime.threads import query_workers

# ---------------------------------------------------------------------------------------------------------------
# No correction


class _FittedZero(Fitted):
    method = "none"

    def __init__(self, points, values):
        self.hull = Hull(points)
        self.n_fiducials = len(points)

    def _predict(self, q, local_q):
        return np.zeros((len(q), 3)), None, None


@dataclass(frozen=True)
class NoCorrection:
    """Baseline: predicts zero corrections everywhere (std None); the hull flags are still reported."""

    name: ClassVar[str] = "none"
    reproduces_constants: ClassVar[bool] = False

    def fit(self, points, values) -> FittedInterpolator:
        p, v = check_data(points, values)
        return _FittedZero(p, v)


# ---------------------------------------------------------------------------------------------------------------
# Inverse distance weighting


class _FittedIDW(Fitted):
    method = "idw"

    def __init__(self, points, values, k, power):
        from scipy.spatial import cKDTree

        self.hull = Hull(points)
        self.n_fiducials = len(points)
        self.points = points
        self.values = values
        self.k = min(k, len(points))
        self.power = power
        self.tree = cKDTree(points)

    def _predict(self, q, local_q):
        m, k = len(q), self.k
        out = np.empty((m, 3))
        if m == 0:
            return out, None, None
        d, idx = self.tree.query(q, k=k, workers=query_workers(m))
        d = np.asarray(d, dtype=float).reshape(m, k)
        idx = np.asarray(idx).reshape(m, k)

        # Queries on a fiducial (distance < EXACT_MM, judged on the directly computed distance).
        exact = np.zeros(m, dtype=bool)
        cand = np.flatnonzero(d[:, 0] < 2 * EXACT_MM)
        if len(cand):
            lists = self.tree.query_ball_point(q[cand], r=2 * EXACT_MM)
            counts = np.array([len(lst) for lst in lists], dtype=int)
            qi = np.repeat(np.arange(len(cand)), counts)
            fi = np.fromiter((j for lst in lists for j in lst), dtype=int, count=int(counts.sum()))
            keep = np.linalg.norm(q[cand][qi] - self.points[fi], axis=1) < EXACT_MM
            qi, fi = qi[keep], fi[keep]
            n_on = np.bincount(qi, minlength=len(cand))
            sums = np.zeros((len(cand), 3))
            np.add.at(sums, qi, self.values[fi])
            on = n_on > 0
            exact[cand[on]] = True
            out[cand[on]] = sums[on] / n_on[on, None]

        rest = ~exact
        if np.any(rest):
            dr = np.maximum(d[rest], np.finfo(float).tiny)
            # w_j = d_j^-p, normalised; written as (d_0 / d_j)^p in (0, 1] so that it never overflows.
            w = np.power(dr[:, :1] / dr, self.power)
            w /= w.sum(axis=1, keepdims=True)
            out[rest] = np.einsum("mk,mkc->mc", w, self.values[idx[rest]])
        return out, None, None


@dataclass(frozen=True)
class IDW:
    """Inverse distance weighting over the k nearest fiducials (3-D distance, sensor frame), weights 1/d^power."""

    name: ClassVar[str] = "idw"
    #: fitted to ones, it predicts ones everywhere (weights that sum to one; tests/interpolation/test_interpolation.py)
    reproduces_constants: ClassVar[bool] = True
    k: int = option(
        4,
        flag="neighbors",
        label="IDW neighbours k",
        help="IDW: number of nearest fiducials (default 4)",
        bounds=(1, 1000),
        ui=(1, 16, 1),
    )
    power: float = option(
        2.0,
        label="IDW power p",
        help="IDW: weight exponent p in 1/d^p (default 2)",
        bounds=(0.0, 50.0),
        lo_open=True,
        ui=(0.5, 6.0, 0.1),
    )

    def __post_init__(self):
        object.__setattr__(self, "k", check_positive_int("idw k (number of nearest fiducials)", self.k))
        object.__setattr__(self, "power", check_float("idw power", self.power, positive=True))
        check_options(self, "idw")

    def fit(self, points, values) -> FittedInterpolator:
        p, v = check_data(points, values)
        return _FittedIDW(p, v, self.k, self.power)
