"""The error slice in the scene: an image on a plane through the work volume, coloured by the predicted error
(`rrbc_core.session.slices`), with the fiducials' hull traced on it in white and unreachable points left clear.

Display only: the values come from `rrbc_core.session.figures.error_slice`; here they are mapped to colours on the heat-map
scale (rigid and RRBC share one scale, so equal colours mean equal millimetres) and placed in the robot frame.
"""

from __future__ import annotations

import numpy as np
import viser

from rrbc_core.session.slices import AXES, ErrorSlice

from . import colors

#: The slice's values as the panel names them -> ErrorSlice value names.
SLICE_CHOICES = (
    ("RRBC error", "rrbc"),
    ("rigid error", "rigid"),
    ("95 % bound", "bound95"),
    ("|ê| (correction)", "correction"),
    ("gp std", "std"),
)
SLICE_AXES = (("horizontal (z)", "z"), ("vertical, across x (x)", "x"), ("vertical, along x (y)", "y"))
UPSAMPLE = 4  # image pixels per grid step (nearest), so the hull's trace is thin
HULL_RGB = (255, 255, 255)

#: Orientation of the image (local x = image columns, local y = image rows upward, local z = its normal) per axis.
_ROTATIONS = {
    "z": np.eye(3),
    "y": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),  # columns: x, z, -y
    "x": np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),  # columns: y, z, x
}


def scale_range(sl: ErrorSlice, value: str) -> tuple[float, float]:
    """The colour scale's ends (mm) for `value`: from 0 to the largest value shown (rigid and RRBC share the
    larger of their maxima)."""
    names = ("rigid", "rrbc") if value in ("rigid", "rrbc") else (value,)
    vals = np.concatenate([sl.values[n].ravel() for n in names])
    vals = vals[np.isfinite(vals)]
    hi = float(vals.max()) if len(vals) else 1.0
    return 0.0, hi if hi > 0 else 1.0


def slice_image(sl: ErrorSlice, value: str) -> tuple[np.ndarray, float, float]:
    """RGBA image (H, W, 4) uint8 of `value` over the slice (row 0 = the plane's top), and the scale's ends."""
    lo, hi = scale_range(sl, value)
    v = sl.values[value]
    n = sl.plane.n
    rgb = colors.scale_colors(v.ravel(), lo, hi).reshape(n, n, 3)
    alpha = np.where(np.isfinite(v), 235, 0).astype(np.uint8)
    img = np.concatenate([rgb, alpha[..., None]], axis=2)
    img = np.repeat(np.repeat(img, UPSAMPLE, 0), UPSAMPLE, 1)
    inside = np.repeat(np.repeat(sl.inside_hull, UPSAMPLE, 0), UPSAMPLE, 1)
    edge = np.zeros_like(inside)
    edge[1:, :] |= inside[1:, :] != inside[:-1, :]
    edge[:, 1:] |= inside[:, 1:] != inside[:, :-1]
    img[edge] = (*HULL_RGB, 255)
    return img[::-1].copy(), lo, hi  # grid rows run upward; image rows downward


def slice_pose(sl: ErrorSlice) -> tuple[np.ndarray, np.ndarray, float, float]:
    """(wxyz, centre (3,) robot frame mm, width, height) of the image node."""
    import viser.transforms as vtf

    p = sl.plane
    centre = np.zeros(3)
    a, b = [i for i in range(3) if i != AXES.index(p.axis)]
    centre[a], centre[b] = 0.5 * (p.lo[0] + p.hi[0]), 0.5 * (p.lo[1] + p.hi[1])
    centre[AXES.index(p.axis)] = p.offset_mm
    wxyz = np.asarray(vtf.SO3.from_matrix(_ROTATIONS[p.axis]).wxyz, float)
    return wxyz, centre, p.hi[0] - p.lo[0], p.hi[1] - p.lo[1]


class SliceNode:
    """The image node of the error slice (created on first show, then updated in place)."""

    def __init__(self, scene: viser.SceneApi, name: str = "/slice/image"):
        self.scene = scene
        self.name = name
        self.handle: viser.ImageHandle | None = None
        self.shape: tuple | None = None

    def show(self, sl: ErrorSlice, value: str) -> tuple[float, float]:
        """Draw `value` of `sl`; returns the colour scale's ends (mm)."""
        img, lo, hi = slice_image(sl, value)
        wxyz, centre, w, h = slice_pose(sl)
        if self.handle is None or self.shape != (w, h, img.shape):
            if self.handle is not None:
                self.handle.remove()
            self.handle = self.scene.add_image(
                self.name, img, w, h, format="png", wxyz=wxyz, position=centre, cast_shadow=False, receive_shadow=False
            )
            self.shape = (w, h, img.shape)
        else:
            self.handle.image = img
            self.handle.wxyz = wxyz
            self.handle.position = centre
        return lo, hi

    def clear(self) -> None:
        self.handle = None
        self.shape = None
