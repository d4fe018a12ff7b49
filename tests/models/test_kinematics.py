"""UR5-like forward/inverse kinematics (rrbc_core.models.kinematics). Positions mm, angles rad unless named _deg."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rrbc_core.errors import InputError
from rrbc_core.models.kinematics import (
    UR5,
    UR5_TOOL_DOWN_SEED,
    DHParameters,
    forward,
    inverse,
    inverse_path,
    perturbed,
    reachable,
    tool_down,
)


# --- an independent forward model: the textbook product of 4x4 DH matrices, one joint at a time -------------
def _rz(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def _rx(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def _trans(x, y, z):
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def _reference_pose(dh, q):
    t = np.eye(4)
    for i in range(6):
        t = t @ _rz(q[i] + dh.theta_offset[i]) @ _trans(0, 0, dh.d[i]) @ _trans(dh.a[i], 0, 0) @ _rx(dh.alpha[i])
    t = t @ _trans(0, 0, dh.tool_mm)
    return t[:3, 3], t[:3, :3]


def _plate(nx=8, ny=10, z=50.0):
    """A 525 x 750 mm plate at z = 50 mm in front of the UR5 (x from -712.5 to -187.5, y from -375 to 375)."""
    xs, ys = np.linspace(-712.5, -187.5, nx), np.linspace(-375.0, 375.0, ny)
    return np.array([[x, y, z] for x in xs for y in ys]), xs, ys


def _rot_angle(r1, r2):
    return np.linalg.norm(Rotation.from_matrix(r1.T @ r2).as_rotvec())


# --- forward ----------------------------------------------------------------------------------------------
def test_ur5_nominal_parameters():
    np.testing.assert_array_equal(UR5.d, [89.159, 0, 0, 109.15, 94.65, 82.3])
    np.testing.assert_array_equal(UR5.a, [0, -425, -392.25, 0, 0, 0])
    np.testing.assert_allclose(UR5.alpha, [np.pi / 2, 0, 0, np.pi / 2, -np.pi / 2, 0])
    assert UR5.tool_mm == 0.0


def test_forward_all_zero_is_textbook_position():
    # q = 0: arm stretched along -x: x = a2 + a3, y = -(d4 + d6), z = d1 - d5.
    p, r = forward(UR5, np.zeros(6))
    np.testing.assert_allclose(p, [-817.25, -191.45, -5.491], atol=1e-9)
    np.testing.assert_allclose(r, [[1, 0, 0], [0, 0, -1], [0, 1, 0]], atol=1e-12)


def test_forward_tool_down_seed_by_hand():
    # q = (0, -90, 90, -90, -90, 0) deg: upper arm up (z = d1 + 425), forearm horizontal along -x (x = -392.25),
    # wrist 2 offset d5 further along -x, wrist 3 (d6) pointing down, y = -d4; tool z axis = -z of the base.
    p, r = forward(UR5, UR5_TOOL_DOWN_SEED)
    np.testing.assert_allclose(p, [-392.25 - 94.65, -109.15, 89.159 + 425 - 82.3], atol=1e-9)
    np.testing.assert_allclose(r[:, 2], [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(r, tool_down(90.0), atol=1e-12)
    # a tool extends the TCP along the flange z axis, i.e. straight down here
    p_tool, _ = forward(UR5.with_tool(120.0), UR5_TOOL_DOWN_SEED)
    np.testing.assert_allclose(p_tool, p + [0, 0, -120.0], atol=1e-9)


def test_forward_matches_independent_dh_product_and_is_vectorised():
    rng = np.random.default_rng(11)
    dh = perturbed(UR5.with_tool(95.0), rng, 1.0, 2.0, 1.0)  # non-trivial offsets, twists and a tool
    q = rng.uniform(-np.pi, np.pi, (4, 5, 6))
    p, r = forward(dh, q)
    assert p.shape == (4, 5, 3) and r.shape == (4, 5, 3, 3)
    for idx in np.ndindex(4, 5):
        p_ref, r_ref = _reference_pose(dh, q[idx])
        np.testing.assert_allclose(p[idx], p_ref, atol=1e-9)
        np.testing.assert_allclose(r[idx], r_ref, atol=1e-12)


def test_forward_rejects_bad_joints():
    with pytest.raises(InputError, match="6 values"):
        forward(UR5, np.zeros(5))
    with pytest.raises(InputError, match="finite"):
        forward(UR5, [0, 0, np.nan, 0, 0, 0])


# --- inverse ----------------------------------------------------------------------------------------------
def test_inverse_forward_round_trip_random_reachable_poses():
    rng = np.random.default_rng(5)
    dh = UR5.with_tool(80.0)
    done = 0
    while done < 40:
        q_true = rng.uniform(-np.pi, np.pi, 6)
        p, r = forward(dh, q_true)
        # Keep configurations clear of the three UR singularities, where neighbouring branches meet and "the
        # seed's branch" is ambiguous: elbow (sin q3 = 0), wrist (sin q5 = 0), shoulder (wrist centre at
        # horizontal distance d4 from the base axis).
        wrist = p - (dh.tool_mm + dh.d[5]) * r[:, 2]
        if min(abs(np.sin(q_true[2])), abs(np.sin(q_true[4]))) < 0.3 or np.hypot(*wrist[:2]) < dh.d[3] + 60:
            continue
        done += 1
        # seeded near the configuration that produced the pose: the solver must return that configuration
        seed = q_true + rng.normal(0, 0.03, 6)
        q = inverse(dh, p, r, seed)
        p2, r2 = forward(dh, q)
        assert np.linalg.norm(p2 - p) < 1e-6
        assert _rot_angle(r, r2) < 1e-9
        np.testing.assert_allclose(q, q_true, atol=1e-6)


def test_inverse_of_an_arm_without_ur_structure():
    # A twist of 0.3 rad on joint 2 breaks the UR structure (no closed form): the solver falls back to
    # continuation from the seed and must still return the configuration near the seed.
    rng = np.random.default_rng(8)
    dh = DHParameters(UR5.a + [0, 0, 0, 15.0, 0, 0], UR5.d, UR5.alpha + [0, 0.3, 0, 0, 0, 0], UR5.theta_offset, 60.0)
    for _ in range(10):
        q_true = UR5_TOOL_DOWN_SEED + rng.uniform(-0.6, 0.6, 6)
        p, r = forward(dh, q_true)
        q = inverse(dh, p, r, q_true + rng.normal(0, 0.03, 6))
        p2, r2 = forward(dh, q)
        assert np.linalg.norm(p2 - p) < 1e-6 and _rot_angle(r, r2) < 1e-9
        np.testing.assert_allclose(q, q_true, atol=1e-6)


def test_inverse_from_a_common_seed_reaches_random_poses_around_the_plate():
    rng = np.random.default_rng(6)
    dh = UR5.with_tool(100.0)
    for _ in range(30):
        p = rng.uniform([-700, -350, 0], [-200, 350, 300])
        r = tool_down(rng.uniform(60, 120)) @ Rotation.from_rotvec(rng.normal(0, 0.2, 3)).as_matrix()
        q = inverse(dh, p, r, UR5_TOOL_DOWN_SEED)
        p2, r2 = forward(dh, q)
        assert np.linalg.norm(p2 - p) < 1e-6 and _rot_angle(r, r2) < 1e-9
        assert np.all(np.abs(q - UR5_TOOL_DOWN_SEED) <= np.pi)  # the representation nearest the seed


def test_inverse_follows_the_seed_branch():
    dh = UR5.with_tool(100.0)
    p, r = np.array([-450.0, 0.0, 50.0]), tool_down(90.0)
    up = inverse(dh, p, r, UR5_TOOL_DOWN_SEED)
    # mirror the elbow: the same pose on the elbow-down branch
    seed_down = forward_elbow_down_seed(dh, up)
    down = inverse(dh, p, r, seed_down)
    for q in (up, down):
        p2, r2 = forward(dh, q)
        assert np.linalg.norm(p2 - p) < 1e-6 and _rot_angle(r, r2) < 1e-9
    assert np.sign(up[2]) == np.sign(UR5_TOOL_DOWN_SEED[2]) and np.sign(down[2]) == -np.sign(up[2])


def forward_elbow_down_seed(dh, q_up):
    """An approximate elbow-down configuration for the same wrist position: flip q3 and compensate q2 and q4
    (planar two-link geometry), used only as a seed."""
    q = q_up.copy()
    l2, l3 = abs(dh.a[1]), abs(dh.a[2])
    q3 = q_up[2]
    # angle of the forearm relative to the upper arm seen from the shoulder
    phi = np.arctan2(l3 * np.sin(q3), l2 + l3 * np.cos(q3))
    q[1] = q_up[1] + 2 * phi
    q[2] = -q3
    q[3] = q_up[3] - (q[1] + q[2] - q_up[1] - q_up[2])
    return q


def test_inverse_unreachable_raises():
    with pytest.raises(InputError, match="not reachable"):
        inverse(UR5, [2000.0, 0.0, 0.0], tool_down(), UR5_TOOL_DOWN_SEED)
    with pytest.raises(InputError, match="rotation"):
        inverse(UR5, [-400.0, 0.0, 50.0], np.diag([1.0, 1.0, -1.0]), UR5_TOOL_DOWN_SEED)
    with pytest.raises(InputError, match="seed_q"):
        inverse(UR5, [-400.0, 0.0, 50.0], tool_down(), np.zeros(5))


# --- inverse_path -----------------------------------------------------------------------------------------
def test_inverse_path_reaches_the_plate_on_one_branch():
    dh = UR5.with_tool(100.0)
    pts, xs, ys = _plate()
    r = tool_down(90.0)
    q = inverse_path(dh, pts, r, UR5_TOOL_DOWN_SEED)
    p2, r2 = forward(dh, q)
    assert np.abs(p2 - pts).max() < 1e-6
    assert max(_rot_angle(r, ri) for ri in r2) < 1e-9
    # Branch indicators (shoulder side via q1 range, elbow sign q3, wrist sign q5) equal the seed's everywhere.
    assert np.all(np.sign(q[:, 2]) == np.sign(UR5_TOOL_DOWN_SEED[2]))
    assert np.all(np.sign(q[:, 4]) == np.sign(UR5_TOOL_DOWN_SEED[4]))
    # Joint-space continuity: solving the plate by continuation (each point seeded from its grid neighbour, steps of
    # 75-83 mm, which cannot jump branches) must give the same joints as the all-from-one-seed solution.
    grid = q.reshape(len(xs), len(ys), 6)
    cont = np.empty_like(grid)
    for i in range(len(xs)):
        for j in range(len(ys)):
            prev = UR5_TOOL_DOWN_SEED if (i, j) == (0, 0) else (cont[i - 1, j] if j == 0 else cont[i, j - 1])
            cont[i, j] = inverse(dh, pts[i * len(ys) + j], r, prev)
    np.testing.assert_allclose(grid, cont, atol=1e-6)


def test_inverse_path_is_independent_of_point_order():
    dh = UR5.with_tool(100.0)
    pts, _, _ = _plate(5, 6)
    perm = np.random.default_rng(2).permutation(len(pts))
    rots = np.stack([tool_down(60 + k) for k in range(len(pts))])
    q = inverse_path(dh, pts, rots, UR5_TOOL_DOWN_SEED)
    q_perm = inverse_path(dh, pts[perm], rots[perm], UR5_TOOL_DOWN_SEED)
    np.testing.assert_allclose(q_perm, q[perm], atol=1e-9)


def test_inverse_path_names_unreachable_points():
    pts, _, _ = _plate(3, 3)
    pts[7] = [1500.0, 0.0, 0.0]
    with pytest.raises(InputError, match=r"point 7 at \(1500"):
        inverse_path(UR5, pts, tool_down(90.0), UR5_TOOL_DOWN_SEED)
    with pytest.raises(InputError, match="rotations"):
        inverse_path(UR5, pts, np.stack([tool_down()] * 2), UR5_TOOL_DOWN_SEED)
    assert inverse_path(UR5, np.zeros((0, 3)), tool_down(), UR5_TOOL_DOWN_SEED).shape == (0, 6)


# --- perturbed, tool_down, DHParameters ---------------------------------------------------------------------
def test_perturbed_with_zero_sigmas_is_nominal():
    dh = UR5.with_tool(50.0)
    assert perturbed(dh, np.random.default_rng(0), 0.0, 0.0, 0.0).same_as(dh)


def test_perturbed_is_seeded_and_has_the_requested_spread():
    a = perturbed(UR5, np.random.default_rng(9))
    b = perturbed(UR5, np.random.default_rng(9))
    assert a.same_as(b) and not a.same_as(UR5)
    # 2000 robots: sample std of each parameter group (6 x 2000 draws) within 5 standard errors of sigma
    # (se of a sample std ~ sigma / sqrt(2n)).
    rng = np.random.default_rng(10)
    draws = [perturbed(UR5, rng, 0.1, 0.2, 0.05) for _ in range(2000)]
    n = 6 * len(draws)
    for name, sigma in (("theta_offset", np.radians(0.1)), ("a", 0.2), ("d", 0.2), ("alpha", np.radians(0.05))):
        dev = np.array([getattr(x, name) - getattr(UR5, name) for x in draws])
        assert abs(np.sqrt(np.mean(dev**2)) - sigma) < 5 * sigma / np.sqrt(2 * n)
    with pytest.raises(InputError, match="link_mm"):
        perturbed(UR5, rng, link_mm=-1.0)


def test_tool_down_orientation():
    for yaw in (0.0, 37.0, 90.0, -120.0):
        r = tool_down(yaw)
        np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
        assert np.linalg.det(r) == pytest.approx(1.0)
        np.testing.assert_allclose(r[:, 2], [0, 0, -1], atol=1e-12)
        np.testing.assert_allclose(r[:, 0], [np.cos(np.radians(yaw)), np.sin(np.radians(yaw)), 0], atol=1e-12)


def test_dh_parameters_validation_and_immutability():
    with pytest.raises(InputError, match="DH parameter a"):
        DHParameters(np.zeros(5), np.zeros(6), np.zeros(6), np.zeros(6))
    with pytest.raises(InputError, match="tool_mm"):
        DHParameters(np.zeros(6), np.zeros(6), np.zeros(6), np.zeros(6), tool_mm=float("nan"))
    with pytest.raises(ValueError):
        UR5.a[0] = 1.0


def test_reachable_says_which_points_inverse_path_would_refuse():
    dh = UR5.with_tool(100.0)
    rng = np.random.default_rng(5)
    pts = rng.uniform([-1200, -1200, -300], [1200, 1200, 1300], (60, 3))
    ok = reachable(dh, pts, tool_down(), UR5_TOOL_DOWN_SEED)
    assert ok.any() and (~ok).any()
    inverse_path(dh, pts[ok], tool_down(), UR5_TOOL_DOWN_SEED)  # the reachable ones all solve
    for i in np.flatnonzero(~ok)[:5]:
        with pytest.raises(InputError, match="not reachable"):
            inverse_path(dh, pts[i : i + 1], tool_down(), UR5_TOOL_DOWN_SEED)
    assert not reachable(dh, [[5000.0, 0.0, 0.0]], tool_down(), UR5_TOOL_DOWN_SEED)[0]


def test_the_reach_bound_holds_and_points_beyond_it_cost_no_solver_work(monkeypatch):
    """Issue 42: one tab dragging a target to (1e9, 1e9, 1e9) mm froze the others while the solver iterated. A point
    beyond `reach_bound` (the triangle inequality over the DH links) is refused without any solver call."""
    from rrbc_core.models import kinematics
    from rrbc_core.models.kinematics import reach_bound

    rng = np.random.default_rng(4)
    arm = UR5.with_tool(120.0)
    p, _ = forward(arm, rng.uniform(-np.pi, np.pi, (5000, 6)))
    bound = reach_bound(arm)
    assert np.linalg.norm(p, axis=1).max() <= bound
    assert np.linalg.norm(p, axis=1).max() > 0.8 * bound  # a bound, not a loose guess

    def no_solver(*args, **kwargs):
        raise AssertionError("the solver ran for a point beyond any reach")

    monkeypatch.setattr(kinematics, "_lm", no_solver)
    monkeypatch.setattr(kinematics, "_continuation", no_solver)
    far = np.array([[1e9, 1e9, 1e9], [bound + 10.0, 0.0, 0.0], [0.0, 0.0, -3 * bound]])
    assert not reachable(arm, far, np.eye(3), UR5_TOOL_DOWN_SEED).any()
    with pytest.raises(InputError, match="not reachable"):
        inverse(arm, far[0], np.eye(3), UR5_TOOL_DOWN_SEED)
