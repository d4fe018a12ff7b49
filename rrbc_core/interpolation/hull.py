"""The fiducials' convex hull: the one answer to "is this point covered?" (issue 25).

`hull_flags` is the extrapolation flag every interpolation method reports, and `covered` / `coverage` /
`assess_coverage` are built on it, so `rrbc correct`, `rrbc plan`, `rrbc scene new`, the app's Explore card and its
Plan tab give the same verdict for the same points:

- fiducials spanning a volume: a point is inside when it lies in their 3-D convex hull (within `HULL_TOL`);
- (nearly) coplanar fiducials (their third principal spread below `geometry.points.PLANAR_RATIO` of the first): a
  point is inside when its projection lies inside their polygon AND it is no farther from their plane than
  `plane_tol_mm` = max(`OFF_PLANE_TOL_MM`, the farthest fiducial's own distance from that plane). A target 100 mm
  above a plate of fiducials is outside, and its distance from the plane is reported (``off_plane_mm``);
- (nearly) collinear fiducials: on the segment and within `plane_tol_mm` of the line;
- coincident fiducials: within the cluster's radius.

`coverage` is the fraction of a region of variability inside, estimated from seeded uniform samples (standard
error at most 0.5 / sqrt(samples)). Any frame, mm (the fiducials and the queries in the same frame)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from rrbc_core.errors import InputError
from rrbc_core.geometry.points import LocalFrame, as_points

if TYPE_CHECKING:
    from scipy.spatial import Delaunay

#: Tolerance of the inside-hull test: local units (RMS fiducial distance from their centroid = 1) for dim 1-3,
#: mm for dim 0.
HULL_TOL = 1e-9
#: Least distance (mm) from the plane (line) of coplanar (collinear) fiducials at which a point is outside their
#: hull: 1 mm, the tolerance within which the library treats a point as lying on a surface
#: (`models.visibility`); it grows to the fiducials' own largest distance from their plane.
OFF_PLANE_TOL_MM = 1.0
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
        own = float(np.max(self.frame.off_axis(points))) if dim in (1, 2) else 0.0
        #: distance (mm) from the fiducials' plane (line) beyond which a point is outside (dim 1, 2)
        self.plane_tol_mm = max(OFF_PLANE_TOL_MM, own)
        self._equations: np.ndarray | None = None  # dim 2/3: built on the first inside test (`equations`)
        if dim == 1:
            self.lo = float(self.local[:, 0].min())
            self.hi = float(self.local[:, 0].max())
        else:
            self.radius = float(np.max(np.linalg.norm(points - self.frame.centroid, axis=1)))

    @property
    def equations(self) -> np.ndarray:
        """(F, dim + 1): the hull's facet equations in local coordinates (dim 2/3; built on first use: a fit whose
        flags are never asked for, as the bounds' transform lever, does not pay for them)."""
        from scipy.spatial import ConvexHull, QhullError

        if self._equations is None:
            try:
                self._equations = ConvexHull(self.local).equations
            except QhullError as exc:  # pragma: no cover - the dim classification should prevent this
                raise self._degenerate(exc) from None
        return self._equations

    def _degenerate(self, exc: Exception) -> InputError:
        return InputError(
            f"cannot triangulate the {len(self.local)} fiducials {dim_words(self.frame.dim)} "
            f"({exc.__class__.__name__}); check for (nearly) degenerate fiducial layouts or use method 'idw'"
        )

    @property
    def tri(self) -> Delaunay:
        """Delaunay triangulation of the local coordinates (dim 2/3; built on first use)."""
        from scipy.spatial import Delaunay, QhullError

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
        if dim in (1, 2):
            extra = extra | (off > self.plane_tol_mm)
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
        The query lies outside the fiducials' hull (module docstring: for coplanar fiducials, outside their polygon
        or farther than `plane_tol_mm` from their plane).
    off_plane_mm : (M,) float
        Distance (mm) from the fiducials' affine hull (plane or line; 0 for a 3-D fiducial set).
    """
    p = as_points(points, "fiducial positions")
    if len(p) == 0:
        raise InputError("no fiducials given: at least 1 is needed for the convex-hull test")
    return Hull(p).flags(as_query(query))


def covered(fiducials: ArrayLike, points: ArrayLike) -> np.ndarray:
    """(M,) bool: the points inside the fiducials' hull (`hull_flags`); all False without fiducials."""
    q = as_query(points) if np.size(points) else np.zeros((0, 3))
    f = as_points(fiducials, "fiducial positions") if np.size(fiducials) else np.zeros((0, 3))
    if len(f) == 0 or len(q) == 0:
        return np.zeros(len(q), dtype=bool)
    return ~hull_flags(f, q)[0]


def coverage(fiducials: ArrayLike, regions: Sequence, *, samples_per_region: int = 512, seed: int = 0) -> np.ndarray:
    """Per region of variability, the fraction of its volume inside the fiducials' hull (`covered`).

    Parameters
    ----------
    fiducials : (N, 3) array_like
        Fiducial positions, mm.
    regions : sequence of regions (or of targets with a ``region``)
        Each with ``sample(rng, n) -> (n, 3)`` uniform samples, mm, in the fiducials' frame.
    samples_per_region : int
        Uniform samples per region (standard error <= 0.5 / sqrt(samples)).
    seed : int
        Seed of the samples.

    Returns
    -------
    (R,) ndarray
        Fractions in [0, 1].
    """
    n = int(samples_per_region)
    if n < 1:
        raise InputError(f"samples_per_region must be >= 1, got {samples_per_region}")
    regs = [getattr(r, "region", r) for r in regions]
    if not regs:
        return np.zeros(0)
    rng = np.random.default_rng(seed)
    samples = np.concatenate([r.sample(rng, n) for r in regs])
    return covered(fiducials, samples).reshape(len(regs), n).mean(axis=1)


@dataclass(frozen=True, eq=False)
class Coverage:
    """Whether each point is inside the fiducials' hull, how far it is from their plane, and (with regions) the
    fraction of its region inside. inside (M,) bool; off_plane_mm (M,) mm (0 for fiducials spanning a volume);
    plane_tol_mm: the distance from the plane beyond which a point is outside (None for a volume); fraction (M,) in
    [0, 1] or None without regions; dim: 0-3, what the fiducials span."""

    inside: np.ndarray
    off_plane_mm: np.ndarray
    plane_tol_mm: float | None
    fraction: np.ndarray | None
    dim: int

    def describe(self, i: int, fraction: float | None = None) -> str:
        """Point i's verdict in words, e.g. "outside the fiducials' hull (105.0 mm off their plane)"; with its
        region's fraction inside (`fraction`, else this Coverage's own) "...; 49 % of its region inside"."""
        words = "inside the fiducials' hull" if self.inside[i] else "outside the fiducials' hull"
        if self.plane_tol_mm is not None and self.off_plane_mm[i] > self.plane_tol_mm:
            words += f" ({self.off_plane_mm[i]:.1f} mm off their {'plane' if self.dim == 2 else 'line'})"
        if fraction is None and self.fraction is not None:
            fraction = float(self.fraction[i])
        if fraction is not None:
            words += f"; {100 * fraction:.0f} % of its region inside"
        return words


def assess_coverage(
    fiducials: ArrayLike,
    points: ArrayLike,
    regions: Sequence | None = None,
    *,
    samples_per_region: int = 512,
    seed: int = 0,
) -> Coverage:
    """The coverage verdict of every caller (module docstring): inside or outside, distance from the fiducials'
    plane, and with `regions` (one per point) the fraction of each region inside.

    Parameters
    ----------
    fiducials : (N, 3) array_like
        Fiducial positions, mm (N >= 1).
    points : (M, 3) array_like
        The points judged (targets, checks), mm, same frame.
    regions : sequence of M regions, optional
        Their regions of variability (`coverage`).
    samples_per_region, seed : int
        As `coverage`.

    Returns
    -------
    Coverage
    """
    f = as_points(fiducials, "fiducial positions")
    if len(f) == 0:
        raise InputError("no fiducials given: at least 1 is needed for the convex-hull test")
    q = as_query(points) if np.size(points) else np.zeros((0, 3))
    hull = Hull(f)
    extra, off = hull.flags(q) if len(q) else (np.zeros(0, bool), np.zeros(0))
    frac = None
    if regions is not None:
        if len(regions) != len(q):
            raise InputError(f"{len(regions)} regions for {len(q)} points: give one region per point")
        frac = coverage(f, regions, samples_per_region=samples_per_region, seed=seed)
    dim = hull.frame.dim
    return Coverage(~extra, off, hull.plane_tol_mm if dim in (1, 2) else None, frac, dim)
