"""What every interpolation method shares: the `Prediction` result, the `FittedInterpolator` protocol, input
and option checks, and the fitted base class (`Fitted`: validate the query, compute the hull flags, delegate
the values). The methods themselves: `idw.py`, `linear.py`, `tps.py`, `gp.py`; the package docstring says how
they work and in which coordinates."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.geometry.points import COINCIDENT_MM, LocalFrame, as_points
from rrbc_core.interpolation.hull import Hull, as_query, dim_words  # noqa: F401 - re-exported

#: A query closer than this (mm) to a fiducial takes that fiducial's correction in IDW.
EXACT_MM = 1e-9
#: Elements per temporary array when processing queries in chunks (bounds memory for large query sets).
CHUNK_ELEMENTS = 2_000_000


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

    def values_at(self, query) -> np.ndarray: ...


# ---------------------------------------------------------------------------------------------------------------
# Input checks


def check_data(points, values) -> tuple[np.ndarray, np.ndarray]:
    p = as_points(points, "fiducial positions")
    v = as_points(values, "fiducial corrections")
    if len(p) != len(v):
        raise InputError(
            f"{len(p)} fiducial positions but {len(v)} correction vectors: give one correction per fiducial"
        )
    if len(p) == 0:
        raise InputError("no fiducials given: at least 1 is needed to interpolate corrections")
    return p, v


def too_few(method: str, needed: int, frame_dim: int, given: int, why: str = "") -> InputError:
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


def coincident_groups(local: np.ndarray, tol: float) -> np.ndarray:
    """Group label per point: points closer than tol (chained) share a label (labels 0..G-1)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    pairs = cKDTree(local).query_pairs(tol, output_type="ndarray")
    n = len(local)
    if len(pairs) == 0:
        return np.arange(n)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)[1]


#: Fiducials closer than this fraction of their set's RMS radius (local units) are one place for the exact
#: interpolators (tps, linear): their positions and corrections are averaged before fitting. Real files hold the same
#: place measured twice — at two stations, or reached in two arm configurations — with corrections that differ by
#: millimetres; an exact interpolant through both has gradients of millimetres per micrometre
#: (tests/interpolation/test_no_blow_up.py). 1e-3 of the radius is 0.3 mm for a 300 mm cell: far below any
#: spacing a user plans, far above a tracker's noise.
NEAR_FRACTION = 1e-3


def near_groups(local: np.ndarray, scale_mm: float) -> np.ndarray:
    """`coincident_groups` at the merge tolerance of the exact interpolators: max(COINCIDENT_MM, NEAR_FRACTION of
    the RMS radius), in local units (`scale_mm`: the local frame's mm per unit)."""
    return coincident_groups(local, max(COINCIDENT_MM / scale_mm, NEAR_FRACTION))


def group_mean(labels: np.ndarray, data: np.ndarray) -> np.ndarray:
    n_groups = int(labels.max()) + 1
    out = np.zeros((n_groups, data.shape[1]))
    np.add.at(out, labels, data)
    return out / np.bincount(labels, minlength=n_groups)[:, None]


# ---------------------------------------------------------------------------------------------------------------
# Option checks


def check_positive_int(name: str, value, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer, float, np.floating)):
        raise InputError(f"{name} must be an integer >= {minimum}, got {value!r}")
    if not np.isfinite(value) or float(value) != int(value) or int(value) < minimum:
        raise InputError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def check_float(name: str, value, *, positive: bool) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer, float, np.floating)):
        raise InputError(f"{name} must be a number, got {value!r}")
    v = float(value)
    if not np.isfinite(v) or (v <= 0 if positive else v < 0):
        raise InputError(f"{name} must be a finite number {'> 0' if positive else '>= 0'}, got {value!r}")
    return v


# ---------------------------------------------------------------------------------------------------------------
# Base for fitted objects


class Fitted:
    """Common predict(): validate the query, compute the hull flags, delegate the values to `_predict`."""

    method: str
    hull: Hull
    n_fiducials: int

    @property
    def frame(self) -> LocalFrame:
        return self.hull.frame

    def predict(self, query) -> Prediction:
        """Corrections (mm, sensor frame) at query points (M x 3 or one 3-vector, sensor frame, mm)."""
        q = as_query(query)
        local_q = self.hull.frame.to_local(q)
        values, std, extra = self._predict(q, local_q)
        if extra is None:
            extra, off = self.hull.flags(q, local_q)
        else:
            off = self.hull.frame.off_axis(q)
        return Prediction(values=values, std=std, extrapolated=np.asarray(extra, bool), off_plane_mm=off)

    def values_at(self, query) -> np.ndarray:
        """The predicted values only (M, 3), without the hull flags `predict` adds (for callers that do not need
        them: the bounds' transform lever)."""
        q = as_query(query)
        return self._predict(q, self.hull.frame.to_local(q))[0]

    def _predict(self, q, local_q):  # pragma: no cover - abstract
        raise NotImplementedError
