"""Camera framing: where a pinhole camera must stand to show a set of points inside part of its image.

Convention (the app's 3-D view, viser/three.js): the camera looks along `forward`, `up` is the world's +z made
orthogonal to it, `right = forward × up`. A world point p (robot frame, mm) seen from a camera at P projects to
normalised device coordinates

    x_ndc = ((p − P)·right) / ((p − P)·forward · tan(fov_x / 2)),   y_ndc = ((p − P)·up) / ((p − P)·forward · tan(fov_y / 2))

with tan(fov_x/2) = aspect · tan(fov_y/2); the image is x, y ∈ [−1, 1]. A panel covering the image's right-hand
`panel_fraction` of its width leaves x ∈ [−1, 1 − 2·panel_fraction] visible.

For a fixed viewing direction every "p inside the window" condition is linear in P (multiply out the positive
depth), so the closest camera position that keeps every point inside the window (with a margin) is the solution
of a small linear programme: maximise P·forward subject to 4 inequalities per point. The camera's look-at point
is then put on its optical axis at the depth of the points' centre (the centre of orbiting).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.geometry.points import as_points

#: Fraction of the image's half-size left free at each edge of the window.
DEFAULT_MARGIN = 0.08


@dataclass(frozen=True)
class CameraPose:
    """A camera: `position` and `look_at` (3,) robot frame, mm; `up` (3,) unit; `fov_y` vertical field of view,
    radians; `aspect` width / height of the image it was framed for."""

    position: np.ndarray
    look_at: np.ndarray
    up: np.ndarray
    fov_y: float
    aspect: float

    @property
    def forward(self) -> np.ndarray:
        d = np.asarray(self.look_at, float) - np.asarray(self.position, float)
        return d / np.linalg.norm(d)


def camera_basis(forward, up=(0.0, 0.0, 1.0)) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(forward, right, up) unit vectors of a camera looking along `forward` with world `up` as its up hint
    (a forward parallel to the hint uses +y of the world as hint instead)."""
    f = np.asarray(forward, float)
    n = np.linalg.norm(f)
    if not np.isfinite(n) or n == 0:
        raise InputError("the camera's viewing direction must be a non-zero vector")
    f = f / n
    hint = np.asarray(up, float)
    if abs(float(f @ hint)) > 0.999 * np.linalg.norm(hint):
        hint = np.array([0.0, 1.0, 0.0])
    r = np.cross(f, hint)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    return f, r, u


def project(points, pose: CameraPose) -> tuple[np.ndarray, np.ndarray]:
    """Normalised device coordinates (N, 2) of `points` (N, 3) robot frame, mm, seen by `pose`, and their depth
    (N,) along the optical axis (mm; ≤ 0 means behind the camera)."""
    p = as_points(points, "points")
    f, r, u = camera_basis(pose.forward, pose.up)
    d = p - np.asarray(pose.position, float)
    depth = d @ f
    ty = np.tan(pose.fov_y / 2.0)
    tx = pose.aspect * ty
    with np.errstate(divide="ignore", invalid="ignore"):
        ndc = np.stack([(d @ r) / (depth * tx), (d @ u) / (depth * ty)], axis=1)
    return ndc, depth


def in_view(points, pose: CameraPose, panel_fraction: float = 0.0, margin: float = 0.0) -> np.ndarray:
    """(N,) bool: each point (N, 3) robot frame, mm, in front of `pose` and inside the part of its image a panel
    over the right-hand `panel_fraction` of the width leaves free, `margin` (a fraction of the half-size) in from
    every edge."""
    ndc, depth = project(points, pose)
    x, y = ndc[:, 0], ndc[:, 1]
    lim = 1.0 - float(margin)
    with np.errstate(invalid="ignore"):
        return (depth > 0) & (x >= -lim) & (x <= lim - 2.0 * float(panel_fraction)) & (np.abs(y) <= lim)


def _inside(p, position, f, r, u, tx, ty, window, min_distance, tol=1e-9) -> bool:
    d = p - position
    depth = d @ f
    if np.any(depth < min_distance - tol):
        return False
    x, y = (d @ r) / (depth * tx), (d @ u) / (depth * ty)
    x_lo, x_hi, y_lo, y_hi = window
    return bool(
        np.all(x >= x_lo - tol) and np.all(x <= x_hi + tol) and np.all(y >= y_lo - tol) and np.all(y <= y_hi + tol)
    )


def _centre(p, position, f, r, u, tx, ty, window, min_distance, rounds: int = 20) -> np.ndarray:
    """Slide the camera sideways (same depth) so the points' extent in the image is centred in the window: the
    tight programme leaves the slack direction's placement arbitrary (points pushed against one edge). Each
    step moves by the extent's offset from the window's centre at the depth of the points' median, halved
    until no point leaves the window."""
    x_lo, x_hi, y_lo, y_hi = window
    cx_w, cy_w = 0.5 * (x_lo + x_hi), 0.5 * (y_lo + y_hi)
    for _ in range(rounds):
        d = p - position
        depth = d @ f
        x, y = (d @ r) / (depth * tx), (d @ u) / (depth * ty)
        off_x = 0.5 * (x.min() + x.max()) - cx_w
        off_y = 0.5 * (y.min() + y.max()) - cy_w
        if abs(off_x) < 1e-4 and abs(off_y) < 1e-4:
            break
        dm = float(np.median(depth))
        move = off_x * tx * dm * r + off_y * ty * dm * u
        for k in range(6):  # perspective: points at other depths shift more or less; shorten the step if needed
            step = position + move / 2**k
            if _inside(p, step, f, r, u, tx, ty, window, min_distance):
                position = step
                break
        else:
            break
    return position


def frame_points(
    points,
    direction,
    fov_y: float,
    aspect: float,
    panel_fraction: float = 0.0,
    margin: float = DEFAULT_MARGIN,
    up=(0.0, 0.0, 1.0),
    min_distance: float = 1.0,
    top_margin: float | None = None,
) -> CameraPose:
    """The closest camera looking along `direction` that shows every point inside the part of the image not
    covered by a panel over the right-hand `panel_fraction` of its width.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        What must be seen (robot frame, mm); N ≥ 1.
    direction : array_like, shape (3,)
        Viewing direction (from the camera towards the points); need not be unit.
    fov_y : float
        Vertical field of view, radians, in (0, π).
    aspect : float
        Image width / height, > 0.
    panel_fraction : float
        Share of the image width, at its right, hidden by the control panel, in [0, 0.8].
    margin : float
        Free border, as a fraction of the window's half-size, in [0, 0.5).
    up : array_like, shape (3,)
        World up hint.
    min_distance : float
        Least distance (mm) between the camera and the nearest point, along the axis.
    top_margin : float, optional
        The free border at the top instead of `margin` (room for labels drawn above their points), in [0, 1).

    Returns
    -------
    CameraPose
        Its look-at point lies on the optical axis at the depth of the points' bounding-box centre. Along the
        direction the points do not fill, they are centred in the window (`_centre`).
    """
    from scipy.optimize import linprog

    p = as_points(points, "points to frame", empty=False)
    if not (0.0 < fov_y < np.pi) or not (aspect > 0) or not (0.0 <= panel_fraction <= 0.8) or not (0 <= margin < 0.5):
        raise InputError("camera framing needs 0 < fov_y < π, aspect > 0, 0 ≤ panel_fraction ≤ 0.8, 0 ≤ margin < 0.5")
    top = margin if top_margin is None else float(top_margin)
    if not 0.0 <= top < 1.0:
        raise InputError("camera framing needs 0 ≤ top_margin < 1")
    f, r, u = camera_basis(direction, up)
    ty = np.tan(fov_y / 2.0)
    tx = aspect * ty
    # the window in ndc, shrunk by the margin on every side
    x_lo, x_hi = -1.0, 1.0 - 2.0 * panel_fraction
    half_x, half_y = 0.5 * (x_hi - x_lo), 1.0
    x_lo, x_hi = x_lo + margin * half_x, x_hi - margin * half_x
    y_lo, y_hi = -1.0 + margin * half_y, 1.0 - top * half_y
    # unknown P; with d = p - P, depth = d·f > 0: a·d ≤ 0 for a in (r - x_hi tx f, -r + x_lo tx f, u - y_hi ty f,
    # -u + y_lo ty f); a·p - a·P ≤ 0  <=>  -a·P ≤ -a·p
    rows = np.stack([r - x_hi * tx * f, -r + x_lo * tx * f, u - y_hi * ty * f, -u + y_lo * ty * f])
    a_ub = np.repeat(-rows, len(p), axis=0)
    b_ub = -np.concatenate([p @ a for a in rows])
    # in front of every point by min_distance: (p - P)·f ≥ min_distance  <=>  P·f ≤ p·f - min_distance
    a_ub = np.vstack([a_ub, np.tile(f, (len(p), 1))])
    b_ub = np.concatenate([b_ub, p @ f - min_distance])
    res = linprog(-f, A_ub=a_ub, b_ub=b_ub, bounds=[(None, None)] * 3, method="highs")
    if res.status != 0:  # pragma: no cover - the programme is always feasible (stand far enough back)
        raise InputError(f"cannot frame these points: {res.message}")
    position = np.asarray(res.x, float)
    position = _centre(p, position, f, r, u, tx, ty, (x_lo, x_hi, y_lo, y_hi), min_distance)
    centre = 0.5 * (p.min(0) + p.max(0))
    depth = max(float((centre - position) @ f), min_distance)
    return CameraPose(position, position + depth * f, u, float(fov_y), float(aspect))
