"""Piecewise-linear interpolation (`Linear`): barycentric in the enclosing Delaunay simplex of the fiducials'
local coordinates, extended linearly outside the hull from well-shaped boundary simplices."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.interpolation.base import (
    CHUNK_ELEMENTS,
    Fitted,
    FittedInterpolator,
    Hull,
    check_data,
    group_mean,
    near_groups,
    too_few,
)

if TYPE_CHECKING:
    from scipy.spatial import Delaunay

#: Linear extension outside the hull never uses a boundary simplex whose shape quality (d!·volume divided by
#: its longest edge to the power d: 0.5 for a right isosceles triangle, 0 for a flat one) is below this. Noisy
#: grids give nearly flat "sliver" simplices along the hull, whose linear extension has huge gradients (a
#: 4x4 plate with 0.01 mm noise extrapolated 21 mm corrections 5 mm outside its hull before this rule).
SLIVER_QUALITY = 0.05

# ---------------------------------------------------------------------------------------------------------------
# Piecewise linear (Delaunay barycentric)


MAX_FIDUCIALS = 200_000  # Delaunay of random 3-D points: 100 000 took 3 s and ~7 simplices a point (issue 16)


class _FittedLinear(Fitted):
    method = "linear"

    def __init__(self, points, values):
        if len(points) > MAX_FIDUCIALS:
            raise InputError(
                f"linear interpolates at most {MAX_FIDUCIALS:,} fiducials (a Delaunay triangulation of them), got "
                f"{len(points):,}: use idw for more"
            )
        self.hull = Hull(points)
        self.n_fiducials = len(points)
        dim = self.hull.frame.dim
        if dim == 0:
            raise too_few("linear", 2, 0, len(points))
        # Fiducials that (nearly) coincide in the interpolation coordinates share their mean correction
        # (`base.NEAR_FRACTION`): no sliver simplex between two readings of one place.
        labels = near_groups(self.hull.local, self.hull.frame.scale)
        means = group_mean(labels, values)
        if dim == 1:
            t = group_mean(labels, self.hull.local)[:, 0]
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
        chunk = max(1, CHUNK_ELEMENTS // (n_s * (d + 1)))
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

    name: ClassVar[str] = "linear"
    #: fitted to ones, it predicts ones everywhere (weights that sum to one; tests/interpolation/test_interpolation.py)
    reproduces_constants: ClassVar[bool] = True

    def fit(self, points, values) -> FittedInterpolator:
        p, v = check_data(points, values)
        return _FittedLinear(p, v)
