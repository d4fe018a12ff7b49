"""The fiducials' convex hull and the extrapolation flags every method reports (`hull_flags`); the package
docstring states the rule for volumes, planes, lines and coincident points."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import ConvexHull, Delaunay, QhullError

from rrbc_core.errors import InputError
from rrbc_core.geometry.points import LocalFrame, as_points

#: Tolerance of the inside-hull test: local units (RMS fiducial distance from their centroid = 1) for dim 1-3,
#: mm for dim 0.
HULL_TOL = 1e-9
#: Elements per temporary array in the inside test (bounds memory for large query sets).
CHUNK_ELEMENTS = 2_000_000
#: Most facet tests (facets x query points) the inside test runs; a hull of uniformly spread fiducials has few
#: facets, one of fiducials on a sphere about two per fiducial (issue 16: refused, not minutes).
HULL_WORK_LIMIT = 20_000_000_000


def dim_words(dim: int) -> str:
    return {1: "along a line", 2: "in a plane", 3: "in a volume"}.get(dim, "")


def as_query(query) -> np.ndarray:
    q = np.asarray(query, dtype=float)
    if q.shape == (3,):
        q = q[None, :]
    return as_points(q, "query points")


# ---------------------------------------------------------------------------------------------------------------
# Hull / extrapolation flags


class Hull:
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
            f"cannot triangulate the {len(self.local)} fiducials {dim_words(self.frame.dim)} "
            f"({exc.__class__.__name__}); check for (nearly) degenerate fiducial layouts or use method 'idw'"
        )

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
        if len(eq) * len(local_q) > HULL_WORK_LIMIT:
            raise InputError(
                f"the extrapolation test would check {len(local_q):,} points against the {len(eq):,} facets of the "
                f"fiducials' hull (more than {HULL_WORK_LIMIT:,} tests): use fewer fiducials or points"
            )
        out = np.empty(len(local_q), dtype=bool)
        chunk = max(1, CHUNK_ELEMENTS // len(eq))
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


def hull_flags(points: ArrayLike, query: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Whether query points lie outside the fiducials' convex hull, and how far they are from its plane.

    Parameters
    ----------
    points : (N, 3) array_like
        Fiducial positions, sensor frame, mm.
    query : (M, 3) or (3,) array_like
        Query points, sensor frame, mm.

    Returns
    -------
    extrapolated : (M,) bool
        The query's projection into the fiducials' local coordinates lies outside their hull (for coplanar
        fiducials: outside the polygon in their plane, judged by the projection).
    off_plane_mm : (M,) float
        Distance (mm) from the fiducials' affine hull (0 for a 3-D fiducial set).
    """
    p = as_points(points, "fiducial positions")
    if len(p) == 0:
        raise InputError("no fiducials given: at least 1 is needed for the convex-hull test")
    return Hull(p).flags(as_query(query))
