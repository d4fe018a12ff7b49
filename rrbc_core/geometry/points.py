"""Shape of point sets: principal axes, degeneracy checks, and the local coordinates used to interpolate.

All points are rows (N x 3) in one frame, in mm.

Documented thresholds (docs/theory.md §1.2, §3.3, §4.6):
- COINCIDENT_MM: two distinct points closer than this are treated as the same point (1e-3 mm = 1 µm).
- COLLINEAR_RATIO: a point set whose second principal spread is below this fraction of its first
  (sigma_2 / sigma_1 of the centred coordinates) is "nearly collinear": the rotation about its line is not
  determined, so registration refuses it.
- SUBSET_DEGENERACY_RATIO: combinatorial averaging drops 3-point subsets whose sigma_2 / sigma_1 is below this
  (docs/theory.md §1.2 recommend ~0.05; near-collinear triples can wreck an element-wise mean).
- PLANAR_RATIO: a set whose third spread is below this fraction of its first is treated as planar
  (a breadboard) and interpolated in its best-fit plane; 0.02 keeps a 750 mm plate measured with 0.1 mm noise
  (ratio ~1e-4) planar while a fixture with 20 mm of height in 750 mm is 3-D.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core.errors import InputError

COINCIDENT_MM = 1e-3
COLLINEAR_RATIO = 0.01
SUBSET_DEGENERACY_RATIO = 0.05
PLANAR_RATIO = 0.02


def as_points(
    points, what: str = "points", *, single: bool = False, empty: bool = True, minimum: int = 0, frame: str = "mm"
) -> np.ndarray:
    """The one point validator: `points` as an (N, 3) float array of finite coordinates, or InputError.

    Parameters
    ----------
    points : array_like
        (N, 3) coordinates; with ``single=True`` one (3,) point is accepted and returned as (1, 3).
    what : str
        What the points are, for the message ("fiducial positions").
    empty : bool
        Whether no points at all (an empty array of any shape) is allowed; it is returned as (0, 3).
    minimum : int
        The least number of points.
    frame : str
        The frame and unit named in the message ("mm", "robot frame, mm").
    """
    try:
        p = np.asarray(points, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{what} must be numbers ({frame})") from None
    if p.size == 0 and p.ndim <= 2 and (p.ndim < 2 or p.shape[-1] in (0, 3)):
        if not empty or minimum > 0:
            raise InputError(f"{what} are empty: at least {max(minimum, 1)} point(s) needed")
        return np.zeros((0, 3))
    if single and p.shape == (3,):
        p = p[None, :]
    if p.ndim != 2 or p.shape[1] != 3:
        raise InputError(f"{what} must be an N x 3 array of coordinates ({frame}), got shape {p.shape}")
    if not np.all(np.isfinite(p)):
        raise InputError(f"{what} contain a non-finite coordinate (NaN or infinity)")
    if len(p) < minimum:
        raise InputError(f"{what}: {len(p)} given, at least {minimum} needed")
    return p


def principal_spreads(points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centroid, singular values (descending) and principal axes (rows) of the centred points."""
    p = np.asarray(points, dtype=float)
    c = p.mean(axis=0)
    _, s, vt = np.linalg.svd(p - c, full_matrices=len(p) < 3)  # never an N x N U for large N
    s = np.concatenate([s, np.zeros(3 - len(s))])
    return c, s, vt


def spread_ratios(points) -> tuple[float, float]:
    """(sigma_2 / sigma_1, sigma_3 / sigma_1) of the centred points; (0, 0) for coincident points."""
    p = np.asarray(points, dtype=float)
    if len(p) > SMALL_SET:  # the singular values of the QR's 3 x 3 R are the points' (Householder: as stable)
        s = np.linalg.svd(np.linalg.qr(p - p.mean(axis=0), mode="r"), compute_uv=False)
    else:
        _, s, _ = principal_spreads(p)
    if s[0] <= 0:
        return 0.0, 0.0
    return float(s[1] / s[0]), float(s[2] / s[0])


def collinear_ratio_batch(triples: np.ndarray) -> np.ndarray:
    """sigma_2 / sigma_1 for a stack of point sets (K, n, 3), vectorised."""
    c = triples - triples.mean(axis=1, keepdims=True)
    s = np.linalg.svd(c, compute_uv=False)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(s[:, 0] > 0, s[:, 1] / np.where(s[:, 0] > 0, s[:, 0], 1.0), 0.0)
    return r


#: sets up to this many points are checked for coincident pairs all at once (N² distances, 2 MB at 500)
SMALL_SET = 500
#: the sweep (`coincident_pairs`) compares each point with at most this many next ones along its direction
SWEEP_WINDOW = 32
#: the sweep's direction and a second one across it: fixed and along no axis or grid diagonal, so a plane or grid of
#: points spreads on them
_SWEEP = np.linalg.qr(np.array([[0.5377, 0.6411, 0.5470], [-0.7412, 0.1291, 0.6589]]).T)[0].T


def coincident_pairs(p: np.ndarray, tol: float = COINCIDENT_MM) -> np.ndarray:
    """Index pairs (K, 2), i < j, of points (N, 3) closer than `tol` (mm).

    Up to `SMALL_SET` points: every pair at once. Above: sort and sweep. Two points closer than tol are closer than
    tol along any direction, so after sorting the points' projections on one direction each point is compared with
    its next neighbours in that order while any of them is within tol along it (and only those within tol along a
    second direction too): O(N log N) with a few vectorised passes, no tree and no scipy import. Where points crowd
    along the direction (more than `SWEEP_WINDOW` within tol of one another) a k-d tree answers instead."""
    n = len(p)
    if n <= SMALL_SET:
        d2 = np.sum((p[:, None, :] - p[None, :, :]) ** 2, axis=-1)
        i, j = np.nonzero(np.triu(d2 < tol**2, k=1))
        return np.column_stack([i, j])
    xy = p @ _SWEEP.T
    order = np.argsort(xy[:, 0])
    xs, ys = xy[order, 0], xy[order, 1]
    found = []
    for k in range(1, SWEEP_WINDOW + 1):
        ahead = xs[k:] - xs[:-k] < tol
        if not ahead.any():
            break
        near = np.flatnonzero(ahead & (np.abs(ys[k:] - ys[:-k]) < tol))  # (closer than tol across the sweep too)
        d2 = np.sum((p[order[near + k]] - p[order[near]]) ** 2, axis=1)
        hit = near[d2 < tol**2]
        found.append(np.column_stack([order[hit], order[hit + k]]))
    else:
        from scipy.spatial import cKDTree

        # crowded along the sweep: the sliding-midpoint tree without compacting builds about 3x faster
        return cKDTree(p, balanced_tree=False, compact_nodes=False).query_pairs(tol, output_type="ndarray")
    pairs = np.concatenate(found) if found else np.zeros((0, 2), int)
    return np.sort(pairs, axis=1)


def check_registration_points(points, what: str = "registration points", minimum: int = 3) -> np.ndarray:
    """Refuse sets that cannot define a rigid transform: too few, coincident, or (nearly) collinear points."""
    p = as_points(points, what)
    if len(p) < minimum:
        raise InputError(f"{what}: {len(p)} given, at least {minimum} distinct points are needed")
    pairs = coincident_pairs(p)
    if len(pairs):
        a, b = sorted(min(map(tuple, pairs)))
        raise InputError(
            f"{what}: points {a + 1} and {b + 1} coincide (closer than {COINCIDENT_MM} mm); "
            "use distinct, well-spread points"
        )
    r2, _ = spread_ratios(p)
    if r2 < COLLINEAR_RATIO:
        raise InputError(
            f"{what} are collinear or nearly so (spread ratio sigma2/sigma1 = {r2:.2g} < {COLLINEAR_RATIO}): "
            "the rotation about their line is undetermined; add a point off that line"
        )
    return p


@dataclass(frozen=True, eq=False)
class LocalFrame:
    """Coordinates for interpolating over a set of points (e.g. fiducials, sensor frame, mm).

    `dim` is 3 for a volume, 2 for a (nearly) planar set, 1 for a (nearly) collinear set. `to_local` maps
    points to the first `dim` principal coordinates, centred on the set's centroid and divided by `scale`
    (the RMS distance from the centroid), so local coordinates are O(1). `off_axis` gives the distance (mm)
    of points from the set's affine hull (zero for dim 3).
    """

    centroid: np.ndarray
    axes: np.ndarray  # (3, 3) principal axes as rows
    scale: float
    dim: int

    @classmethod
    def of(cls, points) -> LocalFrame:
        p = as_points(points, "interpolation points")
        c, s, vt = principal_spreads(p)
        if s[0] <= COINCIDENT_MM:
            dim = 0
        elif s[1] / s[0] < COLLINEAR_RATIO:
            dim = 1
        elif s[2] / s[0] < PLANAR_RATIO:
            dim = 2
        else:
            dim = 3
        scale = float(np.sqrt(np.mean(np.sum((p - c) ** 2, axis=1)))) or 1.0
        return cls(c, vt, scale, dim)

    def to_local(self, points) -> np.ndarray:
        q = np.asarray(points, dtype=float) - self.centroid
        return (q @ self.axes[: self.dim].T) / self.scale

    def off_axis(self, points) -> np.ndarray:
        q = np.asarray(points, dtype=float) - self.centroid
        rest = q @ self.axes[self.dim :].T
        return np.linalg.norm(rest, axis=-1)
