import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from rrbc_core import registration as reg
from rrbc_core.errors import InputError
from rrbc_core.geometry.transforms import RigidTransform
from tests.support.strategies import point_layouts, transforms

NAMES = list(reg.STRATEGIES)


@settings(max_examples=40, deadline=None)
@given(point_layouts(min_points=5, max_points=10), transforms(), st.sampled_from(NAMES))
def test_every_strategy_recovers_exact_transform_from_noise_free_data(sensor, true, name):
    """Noise-free pairs: each strategy's mapping equals (R, t) at arbitrary points, including large rotations
    (near 180°) and coplanar (tilted) plates; rigid mappings are proper rotations, never reflections."""
    robot = true.apply(sensor)
    r = reg.register(name, sensor, robot)
    q = sensor.mean(0) + np.random.default_rng(0).uniform(-1500, 1500, (20, 3))
    np.testing.assert_allclose(r.mapping.apply(q), true.apply(q), atol=1e-6)
    np.testing.assert_allclose(r.mapping.apply_inverse(true.apply(q)), q, atol=1e-6)
    assert r.fre_rms_mm < 1e-6
    assert np.linalg.det(r.mapping.rotation) == pytest.approx(1.0)
    np.testing.assert_allclose(r.mapping.rotation, true.rotation, atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(point_layouts(min_points=3, max_points=8), transforms(), st.integers(0, 10_000))
def test_least_squares_never_reflects_on_noisy_coplanar_points(sensor, true, seed):
    """Coplanar sets make the plain SVD solution V Uᵀ a reflection about half the time; Umeyama's fix must hold.
    Noise is 1e-3 of the set's RMS radius f, so the rotation error is of order σ/f ~ 1e-3 rad and a flipped
    solution (error ~π) is far beyond the 0.05 rad bound."""
    rng = np.random.default_rng(seed)
    plate = sensor.copy()
    plate -= plate.mean(0)
    _, _, vt = np.linalg.svd(plate)
    plate = plate - np.outer(plate @ vt[2], vt[2])  # project exactly onto a plane
    radius = np.sqrt(np.mean(np.sum(plate**2, axis=1)))
    robot = true.apply(plate) + rng.normal(0, 1e-3 * radius, plate.shape)
    r = reg.least_squares(plate, robot)
    assert np.linalg.det(r.mapping.rotation) == pytest.approx(1.0)
    assert Rotation.from_matrix(r.mapping.rotation.T @ true.rotation).magnitude() < 0.05


def test_least_squares_matches_scipy_align_vectors_with_weights():
    rng = np.random.default_rng(3)
    s = rng.uniform(-300, 300, (12, 3))
    true = RigidTransform(Rotation.from_rotvec([0.4, 1.2, -2.0]).as_matrix(), [10, 20, 30])
    b = true.apply(s) + rng.normal(0, 0.3, s.shape)
    w = rng.uniform(0.2, 2.0, 12)
    r = reg.least_squares(s, b, weights=w)
    wn = w / w.sum()
    sc, bc = s - wn @ s, b - wn @ b
    ref, _ = Rotation.align_vectors(bc, sc, weights=w)
    np.testing.assert_allclose(r.mapping.rotation, ref.as_matrix(), atol=1e-10)
    np.testing.assert_allclose(r.mapping.translation, wn @ b - ref.as_matrix() @ (wn @ s), atol=1e-8)


def test_similarity_scale_is_recovered():
    rng = np.random.default_rng(4)
    s = rng.uniform(-300, 300, (10, 3))
    true = RigidTransform(Rotation.from_rotvec([0.1, 0.2, 0.3]).as_matrix(), [1, 2, 3])
    scale = 1 + 250e-6
    b = true.rotation @ (scale * s).T
    b = b.T + true.translation
    r = reg.least_squares(s, b, with_scale=True)
    assert r.details["scale"] == pytest.approx(scale, rel=1e-12)
    assert r.fre_rms_mm < 1e-9


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize(
    "points, why",
    [
        (np.array([[0.0, 0, 0], [100, 0, 0]]), "at least 3"),
        (np.array([[0.0, 0, 0], [100, 0, 0], [200, 0.0, 0], [300, 0, 0]]), "collinear"),
        (np.array([[0.0, 0, 0], [100, 0, 0], [200, 0.1, 0], [300, 0, 0]]), "collinear"),
        (np.array([[0.0, 0, 0], [100, 0, 0], [100, 0, 0], [0, 100, 0]]), "coincide"),
        (np.array([[0.0, 0, 0], [100, np.nan, 0], [0, 100, 0]]), "non-finite"),
    ],
)
def test_degenerate_sets_raise_clear_errors(name, points, why):
    with pytest.raises(InputError, match=why):
        reg.register(name, points, points + 5.0)


def test_unknown_strategy_lists_valid_names():
    with pytest.raises(InputError, match="least-squares"):
        reg.register("magic", np.eye(3) * 100, np.eye(3) * 100)


def _grid():
    x, y = np.meshgrid(np.linspace(0, 750, 4), np.linspace(0, 525, 4))
    return np.c_[x.ravel(), y.ravel(), np.zeros(16)]


def test_combinatorial_rejects_the_44_collinear_triples_of_a_4x4_grid():
    """Theory notes §3.3: 44 of the C(16,3) = 560 triples of a 4x4 grid are exactly collinear."""
    g = _grid()
    r = reg.combinatorial(g, g + 1.0)
    assert r.details["subsets_rejected"] == 44
    assert r.details["subsets_used"] == 560 - 44


def test_elementwise_and_chordal_averages_agree_at_robot_noise_levels():
    rng = np.random.default_rng(5)
    g = _grid()
    true = RigidTransform(Rotation.from_rotvec([0, 0, 0.5]).as_matrix(), [100, 200, 0])
    b = true.apply(g) + rng.normal(0, 0.05, g.shape)
    ew = reg.combinatorial(g, b, average="elementwise")
    ch = reg.combinatorial(g, b, average="chordal")
    sv = np.linalg.svd(ew.mapping.matrix, compute_uv=False)
    assert np.abs(sv - 1).max() < 1e-4  # element-wise average is not exactly a rotation, but close
    assert np.abs(sv - 1).max() > 0  # ...and it is used as published, not projected
    np.testing.assert_allclose(ew.mapping.apply(g), ch.mapping.apply(g), atol=0.01)


def test_three_point_puts_all_error_on_the_first_point_and_direction():
    s = np.array([[0.0, 0, 0], [300, 0, 0], [0, 200, 0], [300, 200, 0]])
    b = s.copy()
    b[0] += [0.5, 0.0, 0.0]  # shift the origin point along x: the frame moves with it
    r = reg.three_point(s, b)
    np.testing.assert_allclose(r.residuals[0], 0, atol=1e-12)  # the origin is matched exactly


def test_annealing_is_seeded_and_never_worse_than_its_start():
    rng = np.random.default_rng(6)
    s = np.array([[0.0, 0, 0], [750, 0, 0], [0, 525, 0]])
    b = s + rng.normal(0, 0.1, s.shape)
    a1 = reg.annealing(s, b, seed=11, iterations=2000)
    a2 = reg.annealing(s, b, seed=11, iterations=2000)
    np.testing.assert_array_equal(a1.mapping.apply(s), a2.mapping.apply(s))
    assert a1.details["cost_final_mm2"] <= a1.details["cost_initial_mm2"]
    ls = reg.least_squares(s, b)
    assert a1.details["cost_final_mm2"] >= np.sum(ls.residuals**2) - 1e-9  # LS is the optimum of that cost
    polished = reg.annealing(s, b, seed=11, iterations=500, polish=True)
    assert polished.details["cost_final_mm2"] == pytest.approx(np.sum(ls.residuals**2), rel=1e-3, abs=1e-8)


def test_clustering_is_piecewise_and_recovers_two_planted_transforms():
    """Two far-apart groups related by different rigid transforms: each piece recovers its own exactly."""
    rng = np.random.default_rng(7)
    left = rng.uniform(0, 100, (5, 3))
    right = rng.uniform(0, 100, (5, 3)) + [2000, 0, 0]
    t1 = RigidTransform(np.eye(3), [1, 2, 3])
    t2 = RigidTransform(Rotation.from_rotvec([0, 0, 0.01]).as_matrix(), [4, 5, 6])
    s = np.vstack([left, right])
    b = np.vstack([t1.apply(left), t2.apply(right)])
    r = reg.clustering(s, b, clusters=2, seed=1)
    assert r.piecewise
    assert r.fre_rms_mm < 1e-9
    q1, q2 = left.mean(0), right.mean(0)
    np.testing.assert_allclose(r.mapping.apply(q1[None]), t1.apply(q1[None]), atol=1e-9)
    np.testing.assert_allclose(r.mapping.apply(q2[None]), t2.apply(q2[None]), atol=1e-9)
    lsq = reg.least_squares(s, b)
    assert lsq.fre_rms_mm > 1.0  # one rigid transform cannot fit both


def test_clustering_on_four_corners_with_two_clusters():
    """The paper's layout: 4 registration points over 750 x 525 mm, 2 clusters."""
    s = np.array([[0.0, 0, 0], [750, 0, 0], [0, 525, 0], [750, 525, 0]])
    rng = np.random.default_rng(8)
    b = s + rng.normal(0, 0.1, s.shape)
    r = reg.clustering(s, b, clusters=2, seed=0)
    assert len(r.mapping.pieces) == 2
    assert all(len(m) >= 3 for m in r.details["members"])
    assert np.all(np.isfinite(r.residuals))


@pytest.mark.parametrize("name", ["combinatorial", "annealing", "clustering"])
def test_subset_strategies_refuse_more_points_than_the_cap_and_accept_the_cap(name):
    """C(N, 3) subsets grow as N³: above reg.MAX_SUBSET_POINTS the strategies refuse with a message that says
    why and what to use instead; at the cap they run."""
    rng = np.random.default_rng(4)
    n = reg.MAX_SUBSET_POINTS
    s = rng.uniform(0, 500, (n + 1, 3))
    b = s @ Rotation.from_rotvec([0.1, 0.2, 0.3]).as_matrix().T + [10.0, 20.0, 30.0]
    opts = {"clusters": 1} if name == "clustering" else ({"iterations": 50} if name == "annealing" else {})
    with pytest.raises(InputError, match=rf"at most {n} points.*least-squares"):
        reg.register(name, s, b, **opts)
    assert reg.register(name, s[:n], b[:n], **opts).fre_rms_mm < 1e-6


def test_batch_combinatorial_refuses_above_the_cap():
    from rrbc_core.simulation import batch

    s = np.random.default_rng(1).uniform(0, 500, (2, reg.MAX_SUBSET_POINTS + 1, 3))
    with pytest.raises(InputError, match="at most"):
        batch.combinatorial_batch(s, s + 1.0)
