"""Thin-plate spline with a linear term (`TPS`), scipy's RBFInterpolator in the fiducials' local coordinates."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from scipy.interpolate import RBFInterpolator
from scipy.linalg import LinAlgError

from rrbc_core.errors import InputError
from rrbc_core.geometry.points import COINCIDENT_MM
from rrbc_core.interpolation.base import (
    Fitted,
    FittedInterpolator,
    Hull,
    check_data,
    check_float,
    coincident_groups,
    group_mean,
    too_few,
)
from rrbc_core.option_specs import check_options, option

# ---------------------------------------------------------------------------------------------------------------
# Thin-plate spline


MAX_FIDUCIALS = 5000  # tps solves a dense (N+4)² system: O(N²) memory, O(N³) time (4000 took 0.9 s; issue 16)


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
        if smoothing == 0:
            # Fiducials that coincide in the interpolation coordinates are merged (mean position and
            # correction): an exact interpolant cannot take two values at one point.
            labels = coincident_groups(x, COINCIDENT_MM / self.hull.frame.scale)
            x, v = group_mean(labels, x), group_mean(labels, v)
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

    name: ClassVar[str] = "tps"
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
