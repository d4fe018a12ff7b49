"""Thin-plate spline with a linear term (`TPS`), scipy's RBFInterpolator in the fiducials' local coordinates."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.interpolation.base import (
    Fitted,
    FittedInterpolator,
    Hull,
    check_data,
    check_float,
    group_mean,
    near_groups,
    too_few,
)
from rrbc_core.option_specs import check_options, option

# ---------------------------------------------------------------------------------------------------------------
# Thin-plate spline


#: A fitted spline may not exceed this multiple of the largest fiducial correction inside the fiducials' box; the
#: smoothing is raised (from SMOOTHING_START, tenfold at most MAX_RAISES times) until it does not.
BOUND_FACTOR = 2.0
SMOOTHING_START = 1e-6
MAX_RAISES = 12
MAX_FIDUCIALS = 5000  # tps solves a dense (N+4)² system: O(N²) memory, O(N³) time (4000 took 0.9 s; issue 16)


def _probes(x: np.ndarray) -> np.ndarray:
    """Probe points (local coordinates) where a spline must stay bounded: a grid over the fiducials' box (10 %
    margin; 16 per side in 2-D, 7 in 3-D, 64 in 1-D) and the midpoints between each fiducial and its nearest
    neighbour."""
    from scipy.spatial import cKDTree

    dim = x.shape[1]
    lo, hi = x.min(axis=0), x.max(axis=0)
    pad = 0.1 * (hi - lo)
    n = {1: 64, 2: 16}.get(dim, 7)
    axes = [np.linspace(a - p, b + p, n) for a, b, p in zip(lo, hi, pad)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, dim)
    if len(x) < 2:
        return grid
    _, nn = cKDTree(x).query(x, k=2)
    return np.vstack([grid, 0.5 * (x + x[nn[:, 1]])])


class _FittedTPS(Fitted):
    method = "tps"

    def __init__(self, points, values, smoothing):
        if len(points) > MAX_FIDUCIALS:
            raise InputError(
                f"tps interpolates at most {MAX_FIDUCIALS} fiducials (its fit is a dense solve, O(N³)), got "
                f"{len(points)}: use idw or linear for more"
            )
        self.hull = Hull(points)
        self.n_fiducials = len(points)
        dim = self.hull.frame.dim
        if dim == 0:
            raise too_few("tps", 2, 0, len(points))
        self.smoothing = smoothing
        x, v = self.hull.local, values
        # Fiducials that (nearly) coincide in the interpolation coordinates are merged (mean position and
        # correction, `base.NEAR_FRACTION`): an exact interpolant cannot take two values at one place.
        labels = near_groups(x, self.hull.frame.scale)
        x, v = group_mean(labels, x), group_mean(labels, v)
        self.smoothing_used = self._bounded(x, v, smoothing)

    def _fit(self, x, v, smoothing):
        from scipy.interpolate import RBFInterpolator
        from scipy.linalg import LinAlgError

        try:
            return RBFInterpolator(x, v, kernel="thin_plate_spline", degree=1, smoothing=smoothing)
        except (LinAlgError, np.linalg.LinAlgError, ValueError) as exc:
            raise InputError(
                f"tps cannot be fitted on these {self.n_fiducials} fiducials ({exc}); use method 'idw' or 'gp'"
            ) from None

    def _bounded(self, x, v, smoothing) -> float:
        """Fit, and while the spline swings beyond BOUND_FACTOR × the largest correction inside the fiducials' box
        (probed on a grid and at the midpoints to each fiducial's nearest neighbour), raise the smoothing tenfold
        from SMOOTHING_START (issue 28: no corrections far beyond the fiducials'). Returns the smoothing used."""
        probes = _probes(x)
        bound = BOUND_FACTOR * float(np.max(np.linalg.norm(v, axis=1))) if len(v) else 0.0
        s = smoothing
        for _ in range(MAX_RAISES + 1):
            self.rbf = self._fit(x, v, s)
            peak = float(np.max(np.linalg.norm(self.rbf(probes), axis=1))) if len(probes) else 0.0
            if peak <= bound or bound == 0.0:
                return s
            s = SMOOTHING_START if s == 0 else 10.0 * s
        return s

    def _predict(self, q, local_q):
        if len(q) == 0:
            return np.zeros((0, 3)), None, None
        return np.asarray(self.rbf(local_q), dtype=float).reshape(len(q), 3), None, None


@dataclass(frozen=True)
class TPS:
    """Thin-plate spline with a linear polynomial part, in local (O(1)) coordinates.

    smoothing >= 0 is scipy's RBFInterpolator smoothing in local units (0: exact interpolation).
    """

    name: ClassVar[str] = "tps"
    #: fitted to ones, it predicts ones everywhere (weights that sum to one; tests/interpolation/test_interpolation.py)
    reproduces_constants: ClassVar[bool] = True
    smoothing: float = option(
        0.0,
        label="TPS smoothing",
        help="TPS: scipy RBF smoothing in the fiducials' local units (default 0: exact interpolation)",
        bounds=(0.0, 1e12),
        ui=(0.0, 1.0, 0.005),
    )

    def __post_init__(self):
        object.__setattr__(self, "smoothing", check_float("tps smoothing", self.smoothing, positive=False))
        check_options(self, "tps")

    def fit(self, points, values) -> FittedInterpolator:
        p, v = check_data(points, values)
        return _FittedTPS(p, v, self.smoothing)
