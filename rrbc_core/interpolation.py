"""Scattered-data interpolation of RRBC correction fields (theory notes §4).

Data: fiducial positions x_i (N x 3, sensor frame, mm) and correction vectors e_i (N x 3, mm). A *method* object
(`IDW`, `Linear`, `TPS`, `GP`, `NoCorrection`: small frozen dataclasses holding options) is fitted with
``method.fit(points, values)`` and the fitted object predicts corrections at query points (targets, sensor
frame, mm) with ``fitted.predict(query) -> Prediction``. `make_interpolator(name, **options)` builds a method
from its command-line name (`METHODS`).

Coordinates. Every method except IDW works in the fiducials' local principal coordinates
(`geometry.LocalFrame`): centred on the fiducial centroid, rotated onto the principal axes, divided by the RMS
distance from the centroid (so they are O(1) and smoothing / length-scale values do not depend on mm), and
truncated to the dimension of the fiducial set:

- dim 3 (a volume): 3-D local coordinates.
- dim 2 (coplanar fiducials, e.g. a breadboard): the 2-D coordinates in the fiducials' best-fit plane. 3-D
  Delaunay and 3-D TPS fail on such sets (the initial simplex is flat / the monomial matrix is rank deficient),
  so the methods interpolate in the plane and a query is *projected* onto it: a target above the plate gets
  the correction of its foot point, because variation normal to the plate is unobservable from coplanar
  fiducials.
- dim 1 (collinear fiducials): the coordinate along the line; `Linear` is piecewise linear along it.
- dim 0 (all fiducials coincide): only a constant can be fitted; IDW (and `NoCorrection`) accept it, the
  other methods raise `InputError`.

IDW follows the published rule literally and uses 3-D Euclidean distances in the sensor frame.

Extrapolation flag (`hull_flags`, shared by every method). A query is *extrapolated* when its projection into
the local coordinates lies outside the convex hull of the fiducials by more than `HULL_TOL` local units (the
hull's facet equations, so queries on a fiducial or on a hull face count as inside; for dim 1 outside
[min, max] by more than `HULL_TOL` local units). **For coplanar fiducials the hull is the 2-D polygon in the
plane and a query is judged by its projection only**: a target 100 mm above the middle of a plate is *not*
flagged, and its distance from the plane is reported separately as ``off_plane_mm`` (distance from the
fiducials' affine hull: plane for dim 2, line for dim 1, zero for dim 3). For dim 0 the hull is the point
cluster itself: ``off_plane_mm`` is the distance from the fiducials' centroid and a query is extrapolated when
that distance exceeds the cluster radius (plus `HULL_TOL` mm).

Methods (theory notes §4.1-4.4):

- `IDW(k, power)`: the k nearest fiducials (3-D distance, sensor frame), weights 1/d^p normalised to sum 1; a
  query closer than `EXACT_MM` to a fiducial takes its correction (the mean if several fiducials are that
  close). Exact at the data, reproduces constants only, tends to the mean of the k nearest far away. No std.
- `Linear()`: barycentric interpolation in the enclosing Delaunay simplex (local coordinates). Outside the hull
  it extends linearly from the "nearest" simplex (the one whose smallest barycentric coordinate is largest)
  instead of returning NaN; such queries are flagged. Reproduces affine fields exactly everywhere. No std.
- `TPS(smoothing)`: `scipy.interpolate.RBFInterpolator` with the thin-plate-spline kernel and a degree-1
  polynomial, in local coordinates (so ``smoothing`` is in the units of local coordinates, independent of mm).
  Exact at the data for smoothing 0; linear precision and linear extrapolation. No std.
- `GP(kernel, noise_mm)`: Gaussian process / universal kriging with a linear mean estimated by generalised least
  squares, Matérn 5/2 (or squared-exponential) kernel and a white-noise term; hyper-parameters shared by the 3
  components and fitted by restricted maximum likelihood (REML). Returns the predictive standard deviation of
  the latent correction (mm), including the trend-uncertainty term of universal kriging.
- `NoCorrection()`: predicts zero corrections (std None); the baseline.

All errors in user input raise `errors.InputError`.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Protocol, runtime_checkable

import numpy as np
from scipy.interpolate import RBFInterpolator
from scipy.linalg import LinAlgError, cho_solve, cholesky, solve_triangular
from scipy.optimize import minimize
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, Delaunay, QhullError, cKDTree
from scipy.spatial.distance import cdist

from .errors import InputError
from .geometry import COINCIDENT_MM, LocalFrame, as_points

#: A query closer than this (mm) to a fiducial takes that fiducial's correction in IDW.
EXACT_MM = 1e-9
#: Tolerance of the inside-hull test: local units (RMS fiducial distance from their centroid = 1) for dim 1-3,
#: mm for dim 0.
HULL_TOL = 1e-9
#: Linear extension outside the hull never uses a boundary simplex whose shape quality (d!·volume divided by
#: its longest edge to the power d: 0.5 for a right isosceles triangle, 0 for a flat one) is below this. Noisy
#: grids give nearly flat "sliver" simplices along the hull, whose linear extension has huge gradients (a
#: 4x4 plate with 0.01 mm noise extrapolated 21 mm corrections 5 mm outside its hull before this rule).
SLIVER_QUALITY = 0.05
#: Elements per temporary array when processing queries in chunks (bounds memory for large query sets).
_CHUNK_ELEMENTS = 2_000_000


# ---------------------------------------------------------------------------------------------------------------
# Results and protocol


@dataclass(frozen=True, eq=False)
class Prediction:
    """Predicted corrections at M query points.

    values: (M, 3) predicted corrections, mm, sensor frame.
    std: (M, 3) predictive standard deviation of the (latent) correction, mm, or None if the method has none.
    extrapolated: (M,) bool, the query's projection lies outside the fiducials' convex hull.
    off_plane_mm: (M,) distance (mm) of the query from the fiducials' affine hull (0 for a 3-D fiducial set).
    """

    values: np.ndarray
    std: np.ndarray | None
    extrapolated: np.ndarray
    off_plane_mm: np.ndarray


@runtime_checkable
class FittedInterpolator(Protocol):
    """A method fitted on fiducials; `predict` takes query points (M x 3 or one 3-vector, sensor frame, mm)."""

    def predict(self, query) -> Prediction: ...


# ---------------------------------------------------------------------------------------------------------------
# Input checks


def _check_data(points, values) -> tuple[np.ndarray, np.ndarray]:
    p = as_points(points, "fiducial positions")
    v = as_points(values, "fiducial corrections")
    if len(p) != len(v):
        raise InputError(
            f"{len(p)} fiducial positions but {len(v)} correction vectors: give one correction per fiducial"
        )
    if len(p) == 0:
        raise InputError("no fiducials given: at least 1 is needed to interpolate corrections")
    return p, v


def _as_query(query) -> np.ndarray:
    q = np.asarray(query, dtype=float)
    if q.shape == (3,):
        q = q[None, :]
    return as_points(q, "query points")


def _too_few(method: str, needed: int, frame_dim: int, given: int, why: str = "") -> InputError:
    if frame_dim == 0:
        return InputError(
            f"{method} needs fiducials at {needed} or more distinct positions, but all {given} given coincide "
            f"(within {COINCIDENT_MM} mm); add fiducials or use method 'idw', which then predicts their mean "
            "correction"
        )
    return InputError(
        f"{method} needs at least {needed} fiducials {why} ({given} given, spanning {frame_dim} dimension(s)); "
        "add fiducials or use method 'idw'"
    )


def _dim_words(dim: int) -> str:
    return {1: "along a line", 2: "in a plane", 3: "in a volume"}.get(dim, "")


def _coincident_groups(local: np.ndarray, tol: float) -> np.ndarray:
    """Group label per point: points closer than tol (chained) share a label (labels 0..G-1)."""
    pairs = cKDTree(local).query_pairs(tol, output_type="ndarray")
    n = len(local)
    if len(pairs) == 0:
        return np.arange(n)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def _group_mean(labels: np.ndarray, data: np.ndarray) -> np.ndarray:
    n_groups = int(labels.max()) + 1
    out = np.zeros((n_groups, data.shape[1]))
    np.add.at(out, labels, data)
    return out / np.bincount(labels, minlength=n_groups)[:, None]


# ---------------------------------------------------------------------------------------------------------------
# Hull / extrapolation flags


class _Hull:
    """Local frame and convex hull of the fiducials (sensor frame, mm) used for the extrapolation flags.

    dim 2/3: the hull's facet equations (unit outward normals n_f and offsets c_f, local coordinates); a query x
    is inside when max_f (n_f·x + c_f) <= HULL_TOL, i.e. no farther than HULL_TOL local units outside any facet.
    That test costs O(facets) per query; Delaunay's `find_simplex` with a tolerance falls back to checking every
    simplex for each query outside the hull (seconds for 100 queries against 100k fiducials). The Delaunay
    triangulation itself is built only when `linear` interpolation asks for it (`tri`)."""

    def __init__(self, points: np.ndarray):
        self.frame = LocalFrame.of(points)
        self.local = self.frame.to_local(points)
        self._tri: Delaunay | None = None
        dim = self.frame.dim
        if dim >= 2:
            try:
                self.equations = ConvexHull(self.local).equations  # (F, dim + 1)
            except QhullError as exc:  # pragma: no cover - the dim classification should prevent this
                raise self._degenerate(exc) from None
        elif dim == 1:
            self.lo = float(self.local[:, 0].min())
            self.hi = float(self.local[:, 0].max())
        else:
            self.radius = float(np.max(np.linalg.norm(points - self.frame.centroid, axis=1)))

    def _degenerate(self, exc: Exception) -> InputError:
        return InputError(
            f"cannot triangulate the {len(self.local)} fiducials {_dim_words(self.frame.dim)} "
            f"({exc.__class__.__name__}); check for (nearly) degenerate fiducial layouts or use method 'idw'")

    @property
    def tri(self) -> Delaunay:
        """Delaunay triangulation of the local coordinates (dim 2/3; built on first use)."""
        if self._tri is None:
            try:
                self._tri = Delaunay(self.local)
            except QhullError as exc:  # pragma: no cover - the dim classification should prevent this
                raise self._degenerate(exc) from None
        return self._tri

    def inside(self, local_q: np.ndarray) -> np.ndarray:
        """(M,) bool: local queries (dim 2/3) inside the hull or within HULL_TOL local units of it."""
        eq = self.equations
        out = np.empty(len(local_q), dtype=bool)
        chunk = max(1, _CHUNK_ELEMENTS // len(eq))
        for start in range(0, len(local_q), chunk):
            x = local_q[start : start + chunk]
            out[start : start + chunk] = np.max(x @ eq[:, :-1].T + eq[:, -1], axis=1) <= HULL_TOL
        return out

    def flags(self, q: np.ndarray, local_q: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        off = self.frame.off_axis(q)
        dim = self.frame.dim
        if local_q is None:
            local_q = self.frame.to_local(q)
        if dim >= 2:
            extra = ~self.inside(local_q)
        elif dim == 1:
            t = local_q[:, 0]
            extra = (t < self.lo - HULL_TOL) | (t > self.hi + HULL_TOL)
        else:
            extra = off > self.radius + HULL_TOL
        return np.asarray(extra, dtype=bool), np.asarray(off, dtype=float)


def hull_flags(points, query) -> tuple[np.ndarray, np.ndarray]:
    """(extrapolated, off_plane_mm) for query points (M x 3 or a 3-vector, sensor frame, mm).

    extrapolated[m] is True when the query's projection into the fiducials' local coordinates lies outside the
    fiducials' convex hull (for coplanar fiducials: outside the 2-D polygon, judged by the projection);
    off_plane_mm[m] is the query's distance (mm) from the fiducials' affine hull (0 for a 3-D fiducial set).
    See the module docstring for the tolerances and the degenerate cases.
    """
    p = as_points(points, "fiducial positions")
    if len(p) == 0:
        raise InputError("no fiducials given: at least 1 is needed for the convex-hull test")
    return _Hull(p).flags(_as_query(query))


# ---------------------------------------------------------------------------------------------------------------
# Option checks


def _check_positive_int(name: str, value, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer, float, np.floating)):
        raise InputError(f"{name} must be an integer >= {minimum}, got {value!r}")
    if not np.isfinite(value) or float(value) != int(value) or int(value) < minimum:
        raise InputError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _check_float(name: str, value, *, positive: bool) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer, float, np.floating)):
        raise InputError(f"{name} must be a number, got {value!r}")
    v = float(value)
    if not np.isfinite(v) or (v <= 0 if positive else v < 0):
        raise InputError(f"{name} must be a finite number {'> 0' if positive else '>= 0'}, got {value!r}")
    return v


# ---------------------------------------------------------------------------------------------------------------
# Base for fitted objects


class _Fitted:
    """Common predict(): validate the query, compute the hull flags, delegate the values to `_predict`."""

    method: str
    hull: _Hull
    n_fiducials: int

    @property
    def frame(self) -> LocalFrame:
        return self.hull.frame

    def predict(self, query) -> Prediction:
        """Corrections (mm, sensor frame) at query points (M x 3 or one 3-vector, sensor frame, mm)."""
        q = _as_query(query)
        local_q = self.hull.frame.to_local(q)
        values, std, extra = self._predict(q, local_q)
        if extra is None:
            extra, off = self.hull.flags(q, local_q)
        else:
            off = self.hull.frame.off_axis(q)
        return Prediction(values=values, std=std, extrapolated=np.asarray(extra, bool), off_plane_mm=off)

    def _predict(self, q, local_q):  # pragma: no cover - abstract
        raise NotImplementedError


# ---------------------------------------------------------------------------------------------------------------
# No correction


class _FittedZero(_Fitted):
    method = "none"

    def __init__(self, points, values):
        self.hull = _Hull(points)
        self.n_fiducials = len(points)

    def _predict(self, q, local_q):
        return np.zeros((len(q), 3)), None, None


@dataclass(frozen=True)
class NoCorrection:
    """Baseline: predicts zero corrections everywhere (std None); the hull flags are still reported."""

    def fit(self, points, values) -> FittedInterpolator:
        p, v = _check_data(points, values)
        return _FittedZero(p, v)


# ---------------------------------------------------------------------------------------------------------------
# Inverse distance weighting


class _FittedIDW(_Fitted):
    method = "idw"

    def __init__(self, points, values, k, power):
        self.hull = _Hull(points)
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
        d, idx = self.tree.query(q, k=k, workers=-1 if m > 5000 else 1)  # large query sets: all cores
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

    k: int = 4
    power: float = 2.0

    def __post_init__(self):
        object.__setattr__(self, "k", _check_positive_int("idw k (number of nearest fiducials)", self.k))
        object.__setattr__(self, "power", _check_float("idw power", self.power, positive=True))

    def fit(self, points, values) -> FittedInterpolator:
        p, v = _check_data(points, values)
        return _FittedIDW(p, v, self.k, self.power)


# ---------------------------------------------------------------------------------------------------------------
# Piecewise linear (Delaunay barycentric)


class _FittedLinear(_Fitted):
    method = "linear"

    def __init__(self, points, values):
        self.hull = _Hull(points)
        self.n_fiducials = len(points)
        dim = self.hull.frame.dim
        if dim == 0:
            raise _too_few("linear", 2, 0, len(points))
        # Fiducials that coincide in the interpolation coordinates share their mean correction.
        labels = _coincident_groups(self.hull.local, COINCIDENT_MM / self.hull.frame.scale)
        means = _group_mean(labels, values)
        if dim == 1:
            t = _group_mean(labels, self.hull.local)[:, 0]
            order = np.argsort(t)
            self.ts, self.vs = t[order], means[order]
        self.values = means[labels]
        if dim >= 2:  # candidates for extension outside the hull: well-shaped simplices near it
            self._boundary = _extension_candidates(self.hull.tri)

    def _predict(self, q, local_q):
        dim = self.hull.frame.dim
        if dim == 1:
            t = local_q[:, 0]
            ts, vs = self.ts, self.vs
            i = np.clip(np.searchsorted(ts, t, side="right") - 1, 0, len(ts) - 2)
            w = ((t - ts[i]) / (ts[i + 1] - ts[i]))[:, None]
            values = (1.0 - w) * vs[i] + w * vs[i + 1]  # linear extension beyond both ends
            return values, None, None

        tri = self.hull.tri
        s = np.asarray(tri.find_simplex(local_q), dtype=int)  # directed walk; -1 outside (or on) the hull
        out = s < 0
        if np.any(out):  # outside: linear extension of the nearest simplex (the same values on the boundary)
            s = s.copy()
            s[out] = self._nearest_simplex(local_q[out])
        bary = self._barycentric(local_q, s)
        values = np.einsum("mj,mjc->mc", bary, self.values[tri.simplices[s]])
        return values, None, None  # flags: the hull test shared by every method

    def _barycentric(self, x: np.ndarray, s: np.ndarray) -> np.ndarray:
        t = self.hull.tri.transform[s]  # (M, d+1, d)
        d = x.shape[1]
        b = np.einsum("mij,mj->mi", t[:, :d, :], x - t[:, d, :])
        return np.concatenate([b, 1.0 - b.sum(axis=1, keepdims=True)], axis=1)

    def _nearest_simplex(self, x: np.ndarray) -> np.ndarray:
        """For queries outside the hull: the simplex whose smallest barycentric coordinate is largest.

        Candidates are the simplices with a face on the hull boundary (the extension is taken from the hull);
        queries are processed in chunks so memory stays bounded.
        """
        tri = self.hull.tri
        cand = self._boundary
        if len(cand) == 0:  # pragma: no cover - a triangulation always has hull faces
            cand = np.arange(len(tri.simplices))
        tr = tri.transform[cand]  # (S, d+1, d)
        n_s, d = tr.shape[0], x.shape[1]
        # b[c, s, :] = T_s (x_c - r_s) = x_c @ T_s^T - T_s r_s: one matrix product per chunk.
        lin = tr[:, :d, :].reshape(n_s * d, d).T  # (d, S*d)
        off = np.einsum("sij,sj->si", tr[:, :d, :], tr[:, d, :])  # (S, d)
        chunk = max(1, _CHUNK_ELEMENTS // (n_s * (d + 1)))
        best = np.empty(len(x), dtype=int)
        for start in range(0, len(x), chunk):
            b = (x[start : start + chunk] @ lin).reshape(-1, n_s, d) - off[None]
            worst = np.minimum(b.min(axis=2), 1.0 - b.sum(axis=2))
            worst = np.where(np.isnan(worst), -np.inf, worst)  # degenerate (flat) simplices never win
            best[start : start + chunk] = cand[np.argmax(worst, axis=1)]
        return best


def _extension_candidates(tri: Delaunay, hops: int = 2) -> np.ndarray:
    """Simplices with a face on the hull, plus those within `hops` neighbour steps of one, minus slivers
    (quality < SLIVER_QUALITY). On a noisy grid the hull faces often belong to slivers only, and the
    well-shaped simplices behind them must carry the extension. Falls back to all simplices if none qualify."""
    near = np.any(tri.neighbors < 0, axis=1)
    for _ in range(hops):
        nb = tri.neighbors[near]
        near = near.copy()
        near[nb[nb >= 0]] = True
    cand = np.flatnonzero(near)
    good = _simplex_quality(tri.points[tri.simplices[cand]]) >= SLIVER_QUALITY
    if np.any(good):
        return cand[good]
    allq = _simplex_quality(tri.points[tri.simplices]) >= SLIVER_QUALITY
    return np.flatnonzero(allq) if np.any(allq) else np.arange(len(tri.simplices))


def _simplex_quality(vertices: np.ndarray) -> np.ndarray:
    """d!·volume / (longest edge)^d for simplices (S, d+1, d): 0 for flat, O(1) for well-shaped ones."""
    d = vertices.shape[-1]
    edges = vertices[:, 1:] - vertices[:, :1]  # (S, d, d)
    vol = np.abs(np.linalg.det(edges))  # d! * volume
    i, j = np.triu_indices(d + 1, k=1)
    longest = np.linalg.norm(vertices[:, i] - vertices[:, j], axis=-1).max(axis=1)
    return vol / np.maximum(longest, np.finfo(float).tiny) ** d


@dataclass(frozen=True)
class Linear:
    """Barycentric interpolation on the Delaunay triangulation of the fiducials (local coordinates).

    Linear extension outside the hull (queries flagged extrapolated); piecewise linear along collinear fiducials.
    """

    def fit(self, points, values) -> FittedInterpolator:
        p, v = _check_data(points, values)
        return _FittedLinear(p, v)


# ---------------------------------------------------------------------------------------------------------------
# Thin-plate spline


class _FittedTPS(_Fitted):
    method = "tps"

    def __init__(self, points, values, smoothing):
        self.hull = _Hull(points)
        self.n_fiducials = len(points)
        dim = self.hull.frame.dim
        if dim == 0:
            raise _too_few("tps", 2, 0, len(points))
        self.smoothing = smoothing
        x, v = self.hull.local, values
        if smoothing == 0:
            # Fiducials that coincide in the interpolation coordinates are merged (mean position and
            # correction): an exact interpolant cannot take two values at one point.
            labels = _coincident_groups(x, COINCIDENT_MM / self.hull.frame.scale)
            x, v = _group_mean(labels, x), _group_mean(labels, v)
        try:
            self.rbf = RBFInterpolator(x, v, kernel="thin_plate_spline", degree=1, smoothing=smoothing)
        except (LinAlgError, np.linalg.LinAlgError, ValueError) as exc:
            raise InputError(
                f"tps cannot be fitted on these {len(points)} fiducials ({exc}); use method 'idw' or 'gp'"
            ) from None

    def _predict(self, q, local_q):
        if len(q) == 0:
            return np.zeros((0, 3)), None, None
        return np.asarray(self.rbf(local_q), dtype=float).reshape(len(q), 3), None, None


@dataclass(frozen=True)
class TPS:
    """Thin-plate spline with a linear polynomial part, in local (O(1)) coordinates.

    smoothing >= 0 is scipy's RBFInterpolator smoothing in local units (0: exact interpolation).
    """

    smoothing: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "smoothing", _check_float("tps smoothing", self.smoothing, positive=False))

    def fit(self, points, values) -> FittedInterpolator:
        p, v = _check_data(points, values)
        return _FittedTPS(p, v, self.smoothing)


# ---------------------------------------------------------------------------------------------------------------
# Gaussian process with a linear mean (universal kriging)

_GP_KERNELS = ("matern52", "se")
_GP_ELL_BOUNDS = (0.05, 20.0)  # length scale, local units (RMS fiducial distance from centroid = 1)
_GP_G_BOUNDS = (1e-8, 1e2)  # g = noise variance / signal variance
_GP_ELL_STARTS = (0.1, 0.3, 1.0, 3.0, 10.0)
_GP_G_STARTS = (1e-6, 1e-3, 1e-1)
_GP_REFINE = 3  # number of best grid starts refined by L-BFGS-B
_GP_FIXED_JITTER = 1e-8  # added to g when the noise is fixed by the user (keeps the Cholesky well posed)
_GP_FLOOR_REL = 1e-9  # residual RMS below this fraction of the correction size counts as zero (clean data)


def _corr(dist: np.ndarray, ell: float, kernel: str) -> tuple[np.ndarray, np.ndarray]:
    """Correlation k(r) for unit signal variance and its derivative with respect to log(ell)."""
    if kernel == "matern52":
        s = np.sqrt(5.0) * dist / ell
        e = np.exp(-s)
        k = (1.0 + s + s * s / 3.0) * e
        dk = (s * s / 3.0) * (1.0 + s) * e
    else:
        u = (dist / ell) ** 2
        k = np.exp(-0.5 * u)
        dk = u * k
    return k, dk


def _design(x: np.ndarray) -> np.ndarray:
    return np.hstack([np.ones((len(x), 1)), x])


def _neg_reml(
    c: np.ndarray, dcs: list[np.ndarray], f: np.ndarray, y: np.ndarray, s2_fixed: float | None, floor: float
):
    """Negative restricted log-likelihood (up to a constant) of Y (N x 3) ~ N(F beta_c, s2_c C), and gradient.

    s2_fixed None: s2_c profiled out per component (floored at `floor`); otherwise s2_c = s2_fixed for all c,
    and `c`, `dcs` already include that factor (C is then the full covariance).
    dcs: derivatives of C with respect to the optimised parameters. Returns (value, grad) or None when a
    Cholesky factorisation fails.
    """
    n, q = f.shape
    try:
        lc = cholesky(c, lower=True)
        ci = cho_solve((lc, True), np.eye(n))
        cif = ci @ f
        a = f.T @ cif
        la = cholesky(a, lower=True)
    except (LinAlgError, np.linalg.LinAlgError, ValueError):
        return None
    p = ci - cif @ cho_solve((la, True), cif.T)
    py = p @ y
    ypy = np.einsum("ic,ic->c", y, py)
    logdet = 2.0 * np.sum(np.log(np.diag(lc))) + 2.0 * np.sum(np.log(np.diag(la)))
    if s2_fixed is None:
        s2 = ypy / (n - q)
        live = s2 > floor
        s2 = np.where(live, s2, floor)
        value = 0.5 * (n - q) * np.sum(np.log(s2)) + 1.5 * logdet
        w = np.where(live, 1.0 / s2, 0.0)
    else:
        value = 0.5 * np.sum(ypy) + 1.5 * logdet
        w = np.ones(y.shape[1])
    grad = np.array([-0.5 * np.einsum("ic,ij,jc,c->", py, dc, py, w) + 1.5 * np.sum(p * dc) for dc in dcs])
    if not (np.isfinite(value) and np.all(np.isfinite(grad))):
        return None
    return float(value), grad


class _FittedGP(_Fitted):
    """A fitted GP. Attributes for reports: length_scale (local units) and length_scale_mm, noise_ratio
    g = sigma_n^2 / sigma_f^2, signal_var (3,) sigma_f^2 per component (mm^2), signal_std_mm and noise_std_mm (3,),
    beta ((dim+1) x 3 trend coefficients in local coordinates). Fitting costs O(N^3) per likelihood evaluation
    (about a hundred evaluations), prediction O(N^2) per query.
    """

    method = "gp"

    def __init__(self, points, values, kernel: str, noise_mm: float | None):
        self.hull = _Hull(points)
        n = len(points)
        self.n_fiducials = n
        dim = self.hull.frame.dim
        if dim == 0 or n < dim + 2:
            raise _too_few("gp", max(dim, 1) + 2, dim, n, f"for fiducials {_dim_words(dim)}")
        self.kernel = kernel
        x = self.hull.local
        f = _design(x)
        q = f.shape[1]
        dist = cdist(x, x)
        eye = np.eye(n)
        # Residual size after an ordinary least-squares plane fit: sets the variance floor and scales.
        resid = values - f @ np.linalg.lstsq(f, values, rcond=None)[0]
        size = float(np.max(np.abs(values))) if np.any(values) else 1.0
        floor = max((_GP_FLOOR_REL * size) ** 2, 1e-300)
        self._x = x

        if noise_mm is None:
            lb = np.log([_GP_ELL_BOUNDS[0], _GP_G_BOUNDS[0]])
            ub = np.log([_GP_ELL_BOUNDS[1], _GP_G_BOUNDS[1]])

            def objective(theta):
                ell, g = np.exp(theta)
                r, dr = _corr(dist, ell, kernel)
                return _neg_reml(r + g * eye, [dr, g * eye], f, values, None, floor)

            starts = [np.log([ell, g]) for ell in _GP_ELL_STARTS for g in _GP_G_STARTS]
        else:
            v = max(float(np.sum(resid**2)) / (3.0 * max(n - q, 1)), noise_mm**2, floor)
            lb = np.log([_GP_ELL_BOUNDS[0], v * 1e-6])
            ub = np.log([_GP_ELL_BOUNDS[1], v * 1e4])
            sn2 = noise_mm**2

            def objective(theta):
                ell, sf2 = np.exp(theta)
                r, dr = _corr(dist, ell, kernel)
                c = sf2 * r + (sn2 + _GP_FIXED_JITTER * sf2) * eye
                return _neg_reml(c, [sf2 * dr, sf2 * (r + _GP_FIXED_JITTER * eye)], f, values, 0.0, floor)

            starts = [np.log([ell, v * r]) for ell in _GP_ELL_STARTS for r in (0.1, 1.0, 10.0)]

        def fun(theta):
            out = objective(theta)
            return (1e300, np.zeros(2)) if out is None else out

        clean = noise_mm is None and np.all(np.sum(resid**2, axis=0) / max(n - q, 1) <= floor)
        if clean:
            # The data are an exact linear field: the likelihood carries no information on (ell, g) and the
            # prediction is the trend whatever they are; keep a well-conditioned deterministic choice.
            best_theta = np.log([1.0, 1e-6])
        else:
            # Deterministic multi-start: evaluate a grid of starts, refine the best few with L-BFGS-B.
            scored = sorted(((fun(t0)[0], i) for i, t0 in enumerate(starts)))
            best_theta, best_val = None, np.inf
            for val0, i in scored[:_GP_REFINE]:
                if val0 >= 1e300:
                    continue
                res = minimize(fun, starts[i], jac=True, method="L-BFGS-B", bounds=list(zip(lb, ub)))
                val = float(res.fun)
                if np.isfinite(val) and val < best_val:
                    best_theta, best_val = np.clip(res.x, lb, ub), val
            if best_theta is None or best_val >= 1e300:  # pragma: no cover - every start failed
                raise InputError(
                    "gp: the covariance matrix could not be factorised for these fiducials; "
                    "check for duplicated fiducials or use method 'idw'"
                )

        ell, h = np.exp(best_theta)
        if noise_mm is None:
            g = h
        else:
            sf2 = h
            g = noise_mm**2 / sf2 + _GP_FIXED_JITTER
        self.length_scale = float(ell)  # local units
        self.length_scale_mm = float(ell * self.hull.frame.scale)
        self.noise_ratio = float(g)  # noise variance / signal variance
        self.fixed_noise = noise_mm is not None

        r, _ = _corr(dist, ell, kernel)
        lc = cholesky(r + g * eye, lower=True)
        fi = solve_triangular(lc, f, lower=True)  # L^-1 F
        yi = solve_triangular(lc, values, lower=True)  # L^-1 Y
        qf, rf = np.linalg.qr(fi)
        beta = solve_triangular(rf, qf.T @ yi)  # GLS trend coefficients (q x 3)
        wres = yi - fi @ beta  # whitened residuals
        if noise_mm is None:
            s2 = np.maximum(np.sum(wres**2, axis=0) / (n - q), floor)
        else:
            s2 = np.full(3, sf2)
        self.signal_var = s2  # (3,) mm^2, per component
        self.signal_std_mm = np.sqrt(s2)
        self.noise_std_mm = np.sqrt(g * s2)
        self.beta = beta
        self._lc, self._rf, self._fi = lc, rf, fi
        self._alpha = solve_triangular(lc.T, wres, lower=False)  # C^-1 (Y - F beta)

    def _predict(self, q, local_q):
        m = len(q)
        values = np.empty((m, 3))
        base = np.empty(m)
        n = len(self._x)
        chunk = max(1, _CHUNK_ELEMENTS // max(n, 1))
        for start in range(0, m, chunk):
            xq = local_q[start : start + chunk]
            kq, _ = _corr(cdist(xq, self._x), self.length_scale, self.kernel)  # (c, N)
            fq = _design(xq)
            values[start : start + chunk] = fq @ self.beta + kq @ self._alpha
            v = solve_triangular(self._lc, kq.T, lower=True)  # (N, c)
            u = fq.T - self._fi.T @ v  # (q, c)
            w = solve_triangular(self._rf, u, trans="T")  # R_f^-T u
            base[start : start + chunk] = 1.0 - np.sum(v * v, axis=0) + np.sum(w * w, axis=0)
        std = np.sqrt(np.maximum(base, 0.0)[:, None] * self.signal_var[None, :])
        return values, std, None


@dataclass(frozen=True)
class GP:
    """Gaussian process (universal kriging) with a linear mean, fitted by REML; hyper-parameters shared by x, y, z.

    kernel: 'matern52' (default) or 'se' (squared exponential), length scale in local units.
    noise_mm: None -> the noise-to-signal variance ratio is estimated (REML); a number >= 0 -> the white-noise
    standard deviation (mm per axis) is fixed to it (e.g. from repeatability measurements) and the signal
    variance, shared by the 3 components, is estimated instead.
    The predictive std is that of the latent correction (without the white noise), in mm.
    """

    kernel: str = "matern52"
    noise_mm: float | None = None

    def __post_init__(self):
        kern = str(self.kernel).strip().lower()
        if kern not in _GP_KERNELS:
            raise InputError(f"unknown gp kernel {self.kernel!r}; valid kernels: {', '.join(_GP_KERNELS)}")
        object.__setattr__(self, "kernel", kern)
        if self.noise_mm is not None:
            object.__setattr__(self, "noise_mm", _check_float("gp noise_mm", self.noise_mm, positive=False))

    def fit(self, points, values) -> FittedInterpolator:
        p, v = _check_data(points, values)
        return _FittedGP(p, v, self.kernel, self.noise_mm)


# ---------------------------------------------------------------------------------------------------------------
# Registry

METHODS = {"idw": IDW, "linear": Linear, "tps": TPS, "gp": GP, "none": NoCorrection}


def make_interpolator(name: str, **options):
    """The method object for a command-line name ('idw', 'linear', 'tps', 'gp', 'none') and its options.

    Options set to None are ignored (they mean "default"); an option the method does not take raises InputError.
    """
    key = str(name).strip().lower()
    if key not in METHODS:
        raise InputError(f"unknown interpolation method {name!r}; valid methods: {', '.join(METHODS)}")
    cls = METHODS[key]
    given = {k: v for k, v in options.items() if v is not None}
    allowed = {fl.name for fl in fields(cls)}
    unknown = sorted(set(given) - allowed)
    if unknown:
        takes = ", ".join(sorted(allowed)) if allowed else "no options"
        raise InputError(f"method {key!r} does not take option(s) {', '.join(unknown)}; it takes: {takes}")
    return cls(**given)
