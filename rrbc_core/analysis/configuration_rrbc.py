"""RRBC over the arm's configuration (docs/calibration.md, "Interpolation space"): `rrbc calibrate`'s RRBC and
VEC+RRBC corrections interpolated between fiducials that are near in JOINT space instead of near in position.

Position-only interpolation cannot follow an error that depends on how the arm reaches a point: the same place
reached with the wrist turned, or elbow up and down, carries another kinematic error, and the fiducials nearest in
position may have been reached the other way. The joint values the file holds separate them.

Metric: joint j's value is scaled by its lever, the mean over the fiducials of |∂p/∂q_j| (the nominal chain's
tool-point Jacobian column, mm per rad or mm per mm), so a distance in joint space is roughly how far the tool point
moves (mm) and a prismatic column mixes with revolute ones in one unit. A joint whose motion barely moves the tool
point (a wrist roll with a short tool) still separates configurations: its lever is at least `MIN_LEVER_SHARE` of
the median lever. The interpolation is IDW as in `rrbc correct` (the k = 4 nearest, weights 1/d²), per station.

Which space each method uses is decided by the cross-validation `rrbc calibrate` already runs over the fiducials
(`choose_spaces`): configuration only where its held-out error is lower than position's by more than `CLEAR_SE`
standard errors of the paired difference (position is the published method and the simpler one, and interpolating
over the joints claims the error follows them: that claim needs clear evidence, as a load term does).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from rrbc_core.models.chain import Chain

#: the methods that interpolate corrections from the fiducials, so have a space
INTERPOLATED = ("rrbc", "vec_rrbc")
#: a joint's lever is at least this share of the median joint's (module docstring)
MIN_LEVER_SHARE = 0.1
K = 4
POWER = 2.0
#: configuration is chosen only where it beats position by more than this many standard errors (module docstring)
CLEAR_SE = 2.0
#: joint-space distances (mm of tool motion) below this are the same configuration
SAME_MM = 1e-9


def configuration_key(method: str) -> str:
    """The key under which `vec_compare.predict_methods` gives `method`'s configuration-space prediction."""
    return f"{method}@configuration"


def joint_levers(chain: Chain, q: np.ndarray) -> np.ndarray:
    """(I,) each input's lever (mm per rad, or mm per mm for a prismatic one): the mean over the poses q (N, I) of
    the nominal chain's tool-point Jacobian column's length, floored at `MIN_LEVER_SHARE` of the median lever."""
    q = np.asarray(q, float)
    if not len(q):
        return np.ones(len(chain.inputs))
    _, _, d_inputs = chain.kinematics(q)
    assert d_inputs is not None
    lever = np.linalg.norm(d_inputs, axis=1).mean(axis=0)
    floor = MIN_LEVER_SHARE * float(np.median(lever))
    return np.maximum(lever, floor if floor > 0 else 1.0)


def configuration_idw(src_q: np.ndarray, values: np.ndarray, dst_q: np.ndarray, levers: np.ndarray) -> np.ndarray:
    """IDW (k = `K`, weights 1/d^`POWER`) of `values` (F, 3) known at joint values src_q (F, I) to dst_q (D, I),
    distances in lever-scaled joint space (module docstring). A query at a fiducial's configuration gets its value."""
    src = np.asarray(src_q, float) * levers
    dst = np.asarray(dst_q, float) * levers
    out = np.zeros((len(dst), 3))
    if not len(dst) or not len(src):
        return out
    k = min(K, len(src))
    d, idx = cKDTree(src).query(dst, k=k)
    d, idx = np.asarray(d, float).reshape(len(dst), k), np.asarray(idx).reshape(len(dst), k)
    exact = d[:, 0] < SAME_MM
    w = 1.0 / np.maximum(d, SAME_MM) ** POWER
    w[exact] = 0.0
    w[exact, 0] = 1.0
    w /= w.sum(axis=1, keepdims=True)
    return np.einsum("nk,nkj->nj", w, np.asarray(values, float)[idx])


def choose_spaces(sq: dict) -> dict[str, str]:
    """Per interpolating method, "configuration" where its held-out squared errors (sq[configuration_key(m)], (H,)
    mm²) are lower than position's (sq[m]) by more than `CLEAR_SE` standard errors of the paired difference, else
    "position" (also with fewer than 2 held-out points)."""
    out = {}
    for m in INTERPOLATED:
        pos, cfg = np.asarray(sq.get(m, ())), np.asarray(sq.get(configuration_key(m), ()))
        if len(pos) < 2 or len(cfg) != len(pos):
            out[m] = "position"
            continue
        d = pos - cfg
        se = float(np.std(d, ddof=1) / np.sqrt(len(d)))
        out[m] = "configuration" if float(np.mean(d)) > CLEAR_SE * se else "position"
    return out


def resolve_spaces(values: dict, spaces: dict[str, str] | None) -> dict:
    """`values` (method -> anything, configuration-space ones under `configuration_key`) with each interpolating
    method's entry taken from its chosen space; the configuration keys are kept."""
    out = dict(values)
    for m, space in (spaces or {}).items():
        if space == "configuration" and configuration_key(m) in values:
            out[m] = values[configuration_key(m)]
    return out


def spaces_json(sq: dict, spaces: dict[str, str]) -> dict:
    """`rrbc calibrate`'s "interpolation_space" object: per interpolating method the chosen space and both spaces'
    cross-validated RMS over the fiducials (mm; null without cross-validation)."""

    def rms(key: str) -> float | None:
        v = np.asarray(sq.get(key, ()))
        return float(np.sqrt(np.mean(v))) if len(v) else None

    return {
        m: {
            "space": spaces.get(m, "position"),
            "cv_rmst_mm": {"position": rms(m), "configuration": rms(configuration_key(m))},
        }
        for m in INTERPOLATED
    }
