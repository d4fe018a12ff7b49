"""Shared hypothesis strategies: rotations (including large ones), translations, point layouts (mm)."""

import numpy as np
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from rrbc_core.geometry.transforms import RigidTransform

finite = dict(allow_nan=False, allow_infinity=False)


@st.composite
def rotations(draw):
    """Uniform-ish rotations from a quaternion, plus explicit near-180° cases."""
    kind = draw(st.sampled_from(["quat", "half_turn"]))
    if kind == "quat":
        q = np.array(draw(st.lists(st.floats(-1, 1, **finite), min_size=4, max_size=4)))
        if np.linalg.norm(q) < 1e-3:
            q = np.array([1.0, 0, 0, 0])
        return Rotation.from_quat(q / np.linalg.norm(q)).as_matrix()
    axis = np.array(draw(st.lists(st.floats(-1, 1, **finite), min_size=3, max_size=3)))
    if np.linalg.norm(axis) < 1e-3:
        axis = np.array([0.0, 0, 1])
    angle = np.pi - draw(st.floats(0, 1e-3, **finite))
    return Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle).as_matrix()


@st.composite
def transforms(draw):
    t = draw(st.lists(st.floats(-2000, 2000, **finite), min_size=3, max_size=3))
    return RigidTransform(draw(rotations()), t)


@st.composite
def point_layouts(draw, min_points=3, max_points=12):
    """Well-conditioned sensor-frame point sets: 3-D clouds or coplanar (tilted) plates, 100–1000 mm."""
    seed = draw(st.integers(0, 2**31 - 1))
    n = draw(st.integers(min_points, max_points))
    planar = draw(st.booleans())
    rng = np.random.default_rng(seed)
    size = draw(st.floats(100, 1000, **finite))
    while True:
        p = rng.uniform(-size / 2, size / 2, (n, 3))
        if planar:
            p[:, 2] = 0.0
            p = p @ Rotation.random(random_state=seed).as_matrix().T
        p += rng.uniform(-1000, 1000, 3)
        c = p - p.mean(0)
        s = np.linalg.svd(c, compute_uv=False)
        if s[1] / s[0] > 0.2 and np.min(np.linalg.norm(c[:, None] - c[None], axis=-1) + np.eye(n) * 1e9) > size / 50:
            return p
