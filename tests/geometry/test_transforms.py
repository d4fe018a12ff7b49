import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from rrbc_core.errors import InputError
from rrbc_core.geometry.transforms import RigidTransform, chordal_mean, mean_transform, project_to_so3
from tests.support.strategies import finite, rotations, transforms


def test_apply_matches_convention_on_known_transform():
    # 90° about z, then shift: sensor x-axis becomes robot y-axis.
    t = RigidTransform([[0, -1, 0], [1, 0, 0], [0, 0, 1]], [10, 20, 30])
    np.testing.assert_allclose(t.apply([1, 0, 0]), [10, 21, 30])
    np.testing.assert_allclose(t.apply_inverse([10, 21, 30]), [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(t.apply([[0, 2, 0], [0, 0, 3]]), [[8, 20, 30], [10, 20, 33]])


@given(
    transforms(), st.lists(st.lists(st.floats(-5000, 5000, **finite), min_size=3, max_size=3), min_size=1, max_size=20)
)
def test_apply_and_apply_inverse_round_trip(t, pts):
    p = np.array(pts)
    np.testing.assert_allclose(t.apply_inverse(t.apply(p)), p, atol=1e-8)
    np.testing.assert_allclose(t.apply(t.apply_inverse(p)), p, atol=1e-8)
    # agrees with the 4x4 homogeneous product
    h = np.c_[p, np.ones(len(p))] @ t.as_matrix().T
    np.testing.assert_allclose(t.apply(p), h[:, :3], atol=1e-8)


@given(transforms(), transforms())
def test_compose_inverse_and_matrix(a, b):
    p = np.array([[1.0, 2.0, 3.0], [-400.0, 50.0, 900.0]])
    np.testing.assert_allclose(a.compose(b).apply(p), a.apply(b.apply(p)), atol=1e-8)
    np.testing.assert_allclose(a.compose(b).as_matrix(), a.as_matrix() @ b.as_matrix(), atol=1e-8)
    np.testing.assert_allclose(a.inverse().apply(p), a.apply_inverse(p), atol=1e-8)
    np.testing.assert_allclose(RigidTransform.from_matrix(a.as_matrix()).as_matrix(), a.as_matrix())
    np.testing.assert_allclose(a.compose(a.inverse()).as_matrix(), np.eye(4), atol=1e-9)


def test_rejects_reflection_and_bad_shapes():
    with pytest.raises(InputError):
        RigidTransform(np.diag([1.0, 1.0, -1.0]), [0, 0, 0])
    with pytest.raises(InputError):
        RigidTransform(np.eye(3) * 1.01, [0, 0, 0])
    with pytest.raises(InputError):
        RigidTransform(np.eye(3), [0, 0])
    with pytest.raises(InputError):
        RigidTransform.from_matrix(np.eye(3))


@settings(max_examples=50)
@given(st.lists(rotations(), min_size=1, max_size=8), st.integers(0, 1000))
def test_chordal_mean_matches_scipy_and_is_a_rotation(rs, seed):
    w = np.random.default_rng(seed).uniform(0.1, 1.0, len(rs))
    m = chordal_mean(np.array(rs), w)
    assert np.linalg.det(m) == pytest.approx(1.0)
    ref = Rotation.from_matrix(np.array(rs)).mean(weights=w).as_matrix()
    # the chordal mean is unique when the weighted mean matrix is non-singular; compare the objective
    obj = lambda r: np.sum(w * np.sum((np.array(rs) - r) ** 2, axis=(1, 2)))
    assert obj(m) <= obj(ref) + 1e-9


def test_chordal_mean_of_small_scatter_is_central():
    rng = np.random.default_rng(0)
    base = Rotation.from_rotvec([0.3, -0.2, 1.0])
    rs = (base * Rotation.from_rotvec(rng.normal(0, 0.01, (200, 3)))).as_matrix()
    m = chordal_mean(rs)
    ang = Rotation.from_matrix(m.T @ base.as_matrix()).magnitude()
    assert ang < 3 * 0.01 * np.sqrt(3) / np.sqrt(200)


def test_project_to_so3_never_reflects():
    m = np.diag([1.0, 1.0, -1.0]) + 1e-3
    r = project_to_so3(m)
    assert np.linalg.det(r) == pytest.approx(1.0)
    np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)


def test_mean_transform_is_exact_at_its_origin():
    a = RigidTransform(Rotation.from_rotvec([0, 0, 0.01]).as_matrix(), [0, 0, 0])
    b = RigidTransform(Rotation.from_rotvec([0, 0, -0.01]).as_matrix(), [1, 0, 0])
    o = np.array([500.0, 0, 0])
    m = mean_transform([a, b], origin=o)
    np.testing.assert_allclose(m.apply(o), (a.apply(o) + b.apply(o)) / 2, atol=1e-12)
