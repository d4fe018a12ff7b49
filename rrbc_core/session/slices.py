"""Error as a field in space: a plane through the work volume, sampled on a grid, with the predicted error at
every grid point (rigid, RRBC, the interpolated correction's size, its gp standard deviation).

Frames and units: robot frame, mm. A `SlicePlane` is normal to one robot axis ("x", "y" or "z") at `offset_mm`
along it, spanning [lo, hi] on the two other axes in their order (x, y for a "z" plane; x, z for "y"; y, z for
"x"); `n` grid points per side. `views.error_slice(session, plane)` fills an `ErrorSlice`: in scene mode
each grid point is measured noise-free through the scene's measurement model (expected sensor reading, bias
included) and corrected with the current fiducials, errors against its truth; points the arm cannot reach have
NaN values. In measurement mode (no truth) only the correction's size and, for gp, its std are known.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core.errors import InputError

AXES = ("x", "y", "z")
#: The in-plane axes of a plane normal to each axis, in image order (columns, rows).
IN_PLANE = {"x": (1, 2), "y": (0, 2), "z": (0, 1)}
MAX_GRID = 160  # points per side: 25 600 points, a few tenths of a second on the bundled scenes
VALUES = ("rigid", "rrbc", "bound95", "correction", "std")


@dataclass(frozen=True)
class SlicePlane:
    """A sampled plane (module docstring). `lo`, `hi` (2,) mm; `n` ≥ 2 and ≤ MAX_GRID."""

    axis: str
    offset_mm: float
    lo: tuple[float, float]
    hi: tuple[float, float]
    n: int = 48

    def __post_init__(self):
        if self.axis not in AXES:
            raise InputError(f"slice axis must be one of x, y, z, got {self.axis!r}")
        lo, hi = np.asarray(self.lo, float).reshape(-1), np.asarray(self.hi, float).reshape(-1)
        if lo.shape != (2,) or hi.shape != (2,) or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise InputError("slice bounds lo and hi must be two finite numbers each (mm)")
        if not np.all(hi > lo):
            raise InputError(f"slice bounds must have hi > lo on both axes, got lo {lo.tolist()}, hi {hi.tolist()}")
        if not np.isfinite(self.offset_mm):
            raise InputError("slice offset must be a finite number of mm")
        n = int(self.n)
        if n != self.n or not (2 <= n <= MAX_GRID):
            raise InputError(f"slice grid size must be an integer from 2 to {MAX_GRID}, got {self.n!r}")
        object.__setattr__(self, "lo", tuple(float(v) for v in lo))
        object.__setattr__(self, "hi", tuple(float(v) for v in hi))
        object.__setattr__(self, "offset_mm", float(self.offset_mm))

    def grid(self) -> np.ndarray:
        """Grid points (n, n, 3) robot frame, mm: [row j, column i] at (u_i, v_j) on the plane's in-plane axes."""
        u = np.linspace(self.lo[0], self.hi[0], self.n)
        v = np.linspace(self.lo[1], self.hi[1], self.n)
        uu, vv = np.meshgrid(u, v)  # (n, n): rows follow v, columns u
        g = np.empty((self.n, self.n, 3))
        a, b = IN_PLANE[self.axis]
        g[..., a], g[..., b] = uu, vv
        g[..., AXES.index(self.axis)] = self.offset_mm
        return g

    def key(self) -> tuple:
        return (self.axis, self.offset_mm, self.lo, self.hi, self.n)


@dataclass(frozen=True, eq=False)
class ErrorSlice:
    """Values on a SlicePlane's grid: `values[name]` (n, n) mm for name in VALUES (NaN where unknown: no truth,
    unreachable, or no gp), `inside_hull` (n, n) bool (inside the included fiducials' hull, in sensor space)."""

    plane: SlicePlane
    points: np.ndarray
    values: dict
    inside_hull: np.ndarray

    def value(self, name: str) -> np.ndarray:
        if name not in VALUES:
            raise InputError(f"slice value must be one of {', '.join(VALUES)}, got {name!r}")
        return self.values[name]


def default_plane(points, axis: str = "z", offset_mm: float | None = None, margin: float = 0.35, n: int = 48):
    """A plane spanning the bounding box of `points` (K, 3) robot frame, mm, widened by `margin` of its size on
    each side (so the field shows what happens outside the fiducials), at `offset_mm` along `axis` (default: the
    points' median there)."""
    p = np.asarray(points, float).reshape(-1, 3)
    if not len(p):
        raise InputError("a slice needs points to span")
    a, b = IN_PLANE[axis] if axis in IN_PLANE else (0, 1)
    lo, hi = p.min(0), p.max(0)
    size = np.maximum(hi - lo, 10.0)
    lo, hi = lo - margin * size, hi + margin * size
    off = float(np.median(p[:, AXES.index(axis)])) if offset_mm is None and axis in AXES else float(offset_mm or 0.0)
    return SlicePlane(axis, off, (lo[a], lo[b]), (hi[a], hi[b]), n)
