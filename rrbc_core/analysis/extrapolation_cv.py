"""Cross-validation that tests extrapolation as extrapolation, and the recommendation rule that weighs it
(docs/calibration.md, "Recommended method").

Ordinary cross-validation over the fiducials predicts each held-out fiducial from neighbours at most one fiducial
spacing away. A check or target beyond the fiducials (outside their hull and farther from the nearest fiducial than
any fiducial lies from its own nearest neighbour, `beyond_points`) is predicted from farther: what a method does
there, ordinary cross-validation does not test. Buffered leave-out folds do (`extrapolation_folds`): for a point
beyond, at distance d from its nearest fiducial a (the anchor, same station, sensor frame), every fiducial within d
of a is left out of the fit and a is predicted from the rest, which all lie farther than d from it. The points
chosen span the distances of the points beyond (evenly by rank), so the folds test extrapolation as far as the
checks and targets need it, in the part of the volume they face. No fold can test a direction the fiducials do not
span: a point off the plane of coplanar fiducials (or off the line of collinear ones) is `untestable`.

`mixture_choice` then chooses the method from both kinds of evidence, weighted by the share of checks and targets
each kind speaks for: the one-standard-error rule (the simplest method whose weighted mean squared error exceeds
the smallest by at most one standard error of the weighted paired difference).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

METHOD_ORDER = ("rigid", "rrbc", "vec", "vec_rrbc")


@dataclass(frozen=True)
class Beyond:
    """The checks and targets beyond what ordinary cross-validation tests (module docstring).

    mask: (P,) bool over the rows to predict; distance_mm: (P,) each one's distance to the nearest fiducial of its
    station (sensor frame; inf where the station has fewer than 2 fiducials); anchor: (P,) that fiducial's index
    into the fiducial rows (-1 where none); untestable: (P,) bool, beyond in a direction the fiducials do not span
    (off their plane or line, `interpolation.hull.Hull.plane_tol_mm`; every point of a station with fewer than 2
    fiducials), where no fold tests anything."""

    mask: np.ndarray
    distance_mm: np.ndarray
    anchor: np.ndarray
    untestable: np.ndarray

    @property
    def share(self) -> float:
        return float(np.mean(self.mask)) if len(self.mask) else 0.0

    @property
    def untestable_share(self) -> float:
        return float(np.mean(self.untestable)) if len(self.untestable) else 0.0


def beyond_points(s, rows_fid, rows_pred, gi=None) -> Beyond:
    """Which of the rows to predict (checks and targets, indices into s (R, 3), sensor frame, mm) lie beyond their
    station's fiducials (rows_fid): outside the fiducials' hull (`interpolation.hull.covered`) and farther from the
    nearest fiducial than any fiducial is from its nearest neighbour. A station with fewer than 2 fiducials counts
    all of its rows. `gi` (R,): each row's station, or None."""
    from scipy.spatial import cKDTree

    from rrbc_core.interpolation.hull import Hull

    rows_pred, rows_fid = np.asarray(rows_pred, int), np.asarray(rows_fid, int)
    mask = np.zeros(len(rows_pred), bool)
    untestable = np.zeros(len(rows_pred), bool)
    dist = np.full(len(rows_pred), np.inf)
    anchor = np.full(len(rows_pred), -1)
    g = np.zeros(len(s), int) if gi is None else np.asarray(gi, int)
    for k in np.unique(g[rows_pred]) if len(rows_pred) else ():
        at = np.flatnonzero(g[rows_pred] == k)
        fid = np.flatnonzero(g[rows_fid] == k)
        if len(fid) < 2:
            mask[at] = untestable[at] = True
            continue
        tree = cKDTree(s[rows_fid[fid]])
        reach = float(np.max(tree.query(s[rows_fid[fid]], k=2)[0][:, 1]))
        d, j = tree.query(s[rows_pred[at]])
        dist[at], anchor[at] = d, fid[j]
        hull = Hull(s[rows_fid[fid]])
        outside, off = hull.flags(s[rows_pred[at]])
        mask[at] = (d > reach) & outside
        untestable[at] = mask[at] & ((hull.frame.dim == 0) | ((hull.frame.dim < 3) & (off > hull.plane_tol_mm)))
    return Beyond(mask, dist, anchor, untestable)


def extrapolation_folds(
    s,
    rows_reg,
    rows_fid,
    beyond: Beyond,
    gi=None,
    *,
    max_folds: int = 20,
    min_registration: int = 3,
    min_poses: int = 8,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Buffered leave-out folds (module docstring) as (left out, scored) index arrays into rows_fid; scored is the
    anchor alone. At most `max_folds`, from points beyond spread evenly over their distances; a fold is dropped when
    it would leave a station fewer than `min_registration` registration rows or the fit fewer than `min_poses`
    registration and fiducial rows (then nothing that far can be tested). Identical folds are kept once."""
    rows_reg, rows_fid = np.asarray(rows_reg, int), np.asarray(rows_fid, int)
    g = np.zeros(len(s), int) if gi is None else np.asarray(gi, int)
    idx = np.flatnonzero(beyond.mask & ~beyond.untestable & (beyond.anchor >= 0))
    if not len(idx):
        return []
    idx = idx[np.argsort(beyond.distance_mm[idx], kind="stable")]
    pick = idx[np.unique(np.round(np.linspace(0, len(idx) - 1, min(max_folds, len(idx)))).astype(int))]
    folds, seen = [], set()
    for p in pick:
        a = int(beyond.anchor[p])
        same = np.flatnonzero(g[rows_fid] == g[rows_fid[a]])
        near = same[np.linalg.norm(s[rows_fid[same]] - s[rows_fid[a]], axis=1) <= beyond.distance_mm[p]]
        key = (a, tuple(near))
        if key in seen:
            continue
        seen.add(key)
        left_reg = np.setdiff1d(rows_reg, rows_fid[near])
        if np.sum(g[left_reg] == g[rows_fid[a]]) < min_registration:
            continue
        if len(np.union1d(left_reg, np.delete(rows_fid, near))) < min_poses:
            continue
        folds.append((near, np.array([a])))
    return folds


def mixture_choice(parts: list[tuple[float, dict]], among: tuple[str, ...] = METHOD_ORDER) -> str:
    """The simplest method (`METHOD_ORDER`) whose weighted mean squared error exceeds the smallest by no more than
    one standard error of the weighted paired difference. parts: (weight, method -> (H,) held-out squared errors,
    mm², the same points for every method) pairs, the weights summing to 1 (the share of the points each part
    speaks for); a part with one point has no spread and adds none to the standard error."""
    among = tuple(m for m in METHOD_ORDER if m in among)

    def score(m: str) -> float:
        return sum(w * float(np.mean(sq[m])) for w, sq in parts)

    best = min(among, key=score)
    for m in among:
        diff = var = 0.0
        for w, sq in parts:
            d = np.asarray(sq[m]) - np.asarray(sq[best])
            diff += w * float(np.mean(d))
            var += w * w * (float(np.var(d, ddof=1)) / len(d) if len(d) > 1 else 0.0)
        if diff <= np.sqrt(var):
            return m
    return best
