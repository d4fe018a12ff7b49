"""Batch (vectorised-over-trials) kernels against the per-trial core functions called in a loop."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rrbc_core import interpolation, registration
from rrbc_core.correction.rrbc import correct_points, fiducial_corrections
from rrbc_core.errors import InputError
from rrbc_core.geometry import points as points_mod
from rrbc_core.geometry.transforms import RigidTransform
from rrbc_core.simulation import batch, batch_checks, batch_registration

TOL = 1e-9  # mm (and for matrices, which multiply coordinates of ~1e3 mm: 1e-12)
REGS = list(registration.STRATEGIES)
INTERPS = list(interpolation.METHODS)


def _layout(rng, n, planar, size=800.0):
    p = rng.uniform(-size / 2, size / 2, (n, 3))
    if planar:
        p[:, 2] = 0.0
        p = p @ Rotation.random(random_state=rng.integers(2**31)).as_matrix().T
    return p + rng.uniform(-1000, 1000, 3)


def _rotation(rng, kind):
    if kind == "half_turn":  # near 180°: the hardest case for naive formulas
        axis = rng.normal(size=3)
        return Rotation.from_rotvec(axis / np.linalg.norm(axis) * (np.pi - 1e-4)).as_matrix()
    return Rotation.random(random_state=rng.integers(2**31)).as_matrix()


def _cell(seed, trials=5, n_reg=7, n_fid=12, n_q=9, planar=False, rot="random", sigma=0.1):
    """T trials of one cell: registration points, fiducials, queries (sensor truth + noise each trial) and
    the robot's view (a rigid transform, a smooth bias and noise). Returns dict of (T, ·, 3) arrays."""
    rng = np.random.default_rng(seed)
    true = RigidTransform(_rotation(rng, rot), rng.uniform(-1500, 1500, 3))
    reg = _layout(rng, n_reg, planar)
    fid = _layout(rng, n_fid, planar, size=600.0)
    q = fid.mean(0) + rng.uniform(-350, 350, (n_q, 3))

    def robot(x):
        b = true.apply(x)
        return b + 0.3 * np.sin(b / 250.0)

    def noisy(x):
        return x[None] + rng.normal(0, sigma, (trials,) + x.shape)

    return {
        "reg_s": noisy(reg),
        "reg_b": noisy(robot(reg)),
        "fid_s": noisy(fid),
        "fid_b": noisy(robot(fid)),
        "query": noisy(q),
        "true": true,
    }


LAYOUTS = [
    dict(seed=1),
    dict(seed=2, planar=True),
    dict(seed=3, rot="half_turn"),
    dict(seed=4, planar=True, rot="half_turn", n_reg=4),
    dict(seed=5, n_reg=3),
]


def _matrix(mapping):
    return mapping.matrix if hasattr(mapping, "matrix") else mapping.rotation


def _assert_same(mapping, a, t, tol=TOL):
    np.testing.assert_allclose(a, _matrix(mapping), rtol=0, atol=tol * 1e-3)
    np.testing.assert_allclose(t, mapping.translation, rtol=0, atol=tol)


# ------------------------------------------------------------------------------------------------------
# Registration kernels
# ------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("layout", LAYOUTS)
@pytest.mark.parametrize("weights", [None, "shared", "per-trial"])
def test_least_squares_batch_equals_loop(layout, weights):
    c = _cell(**layout)
    s, b = c["reg_s"], c["reg_b"]
    rng = np.random.default_rng(7)
    w = {None: None, "shared": rng.uniform(0.2, 2, s.shape[1]), "per-trial": rng.uniform(0.2, 2, s.shape[:2])}[weights]
    a, t = batch.least_squares_batch(s, b, weights=w)
    for k in range(len(s)):
        wk = None if w is None else (w if w.ndim == 1 else w[k])
        _assert_same(registration.least_squares(s[k], b[k], weights=wk).mapping, a[k], t[k])
    np.testing.assert_allclose(np.linalg.det(a), 1.0, atol=1e-12)


def test_least_squares_batch_never_reflects_on_noisy_coplanar_points():
    """Exactly coplanar sensor points with noisy robot points: the plain SVD solution is a reflection about half
    the time; the Umeyama fix must hold in every trial, and the loop must agree."""
    rng = np.random.default_rng(11)
    trials = 200
    plate = _layout(rng, 5, planar=True)
    true = RigidTransform(_rotation(rng, "half_turn"), [100, 200, 300])
    s = np.broadcast_to(plate, (trials, 5, 3)).copy()
    b = true.apply(plate)[None] + rng.normal(0, 0.5, (trials, 5, 3))
    a, t = batch.least_squares_batch(s, b)
    np.testing.assert_allclose(np.linalg.det(a), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("tji,tjk->tik", a, a), np.broadcast_to(np.eye(3), a.shape), atol=1e-12)
    for k in range(0, trials, 20):
        _assert_same(registration.least_squares(s[k], b[k]).mapping, a[k], t[k])


@pytest.mark.parametrize("layout", LAYOUTS)
def test_three_point_batch_equals_loop(layout):
    c = _cell(**layout)
    s, b = c["reg_s"], c["reg_b"]
    a, t = batch.three_point_batch(s, b)
    for k in range(len(s)):
        _assert_same(registration.three_point(s[k], b[k]).mapping, a[k], t[k])
    np.testing.assert_allclose(np.linalg.det(a), 1.0, atol=1e-12)


@pytest.mark.parametrize("layout", LAYOUTS)
@pytest.mark.parametrize("average", ["elementwise", "chordal"])
def test_combinatorial_batch_equals_loop(layout, average):
    c = _cell(**layout)
    s, b = c["reg_s"], c["reg_b"]
    a, t = batch.combinatorial_batch(s, b, average=average)
    for k in range(len(s)):
        _assert_same(registration.combinatorial(s[k], b[k], average=average).mapping, a[k], t[k])


@pytest.mark.parametrize("average", ["elementwise", "chordal"])
def test_combinatorial_batch_rejects_subsets_per_trial(average):
    """A triple whose sigma2/sigma1 sits at the rejection threshold: noise puts it on either side in different
    trials, so the subsets used differ between trials; the batch must decide each trial like the core."""
    rng = np.random.default_rng(5)
    trials = 40
    # points 0, 1, 2: a thin triangle with sigma2/sigma1 close to 0.05; point 3 and 4 well off the line.
    pts = np.array([[0.0, 0, 0], [400, 0, 0], [200, 0, 0], [100, 300, 50], [300, 250, -80]])
    for h in np.linspace(5, 40, 2000):
        pts[2, 1] = h
        if points_mod.collinear_ratio_batch(pts[None, :3])[0] >= 0.05:
            break
    s = pts[None] + rng.normal(0, 0.2, (trials, 5, 3))
    true = RigidTransform(_rotation(rng, "random"), [10, 20, 30])
    b = true.apply(pts)[None] + rng.normal(0, 0.2, (trials, 5, 3))
    a, t = batch.combinatorial_batch(s, b, average=average)
    used = set()
    for k in range(trials):
        ref = registration.combinatorial(s[k], b[k], average=average)
        used.add(ref.details["subsets_used"])
        _assert_same(ref.mapping, a[k], t[k])
    assert len(used) > 1  # the per-trial decisions really differ


@pytest.mark.parametrize("layout", LAYOUTS[:4])
def test_annealing_batch_equals_loop(layout):
    c = _cell(**layout, trials=4)
    s, b = c["reg_s"], c["reg_b"]
    seeds = np.array([0, 7, 123456, 7])
    a, t = batch.annealing_batch(s, b, seeds=seeds, iterations=150, cooling_c=1.5)
    for k in range(len(s)):
        ref = registration.annealing(s[k], b[k], seed=int(seeds[k]), iterations=150, cooling_c=1.5)
        _assert_same(ref.mapping, a[k], t[k])


def test_annealing_batch_from_a_rigid_start():
    """initial=(R, t) from least squares equals annealing(initial=least_squares(...)), chain by chain."""
    c = _cell(seed=9, trials=3)
    s, b = c["reg_s"], c["reg_b"]
    r0, t0 = batch.least_squares_batch(s, b)
    a, t = batch.annealing_batch(s, b, seeds=[3, 4, 5], iterations=120, initial=(r0, t0))
    for k in range(3):
        ref = registration.annealing(
            s[k], b[k], initial=registration.least_squares(s[k], b[k]), seed=3 + k, iterations=120
        )
        _assert_same(ref.mapping, a[k], t[k])
    np.testing.assert_allclose(np.linalg.det(a), 1.0, atol=1e-12)


# ------------------------------------------------------------------------------------------------------
# Mapping points and IDW
# ------------------------------------------------------------------------------------------------------
def test_apply_and_inverse_match_the_core_mappings():
    c = _cell(seed=12)
    s, b, q = c["reg_s"], c["reg_b"], c["query"]
    a, t = batch.combinatorial_batch(s, b)  # element-wise: not a rotation
    assert np.abs(np.einsum("tji,tjk->tik", a, a) - np.eye(3)).max() > 1e-9
    fwd = batch.apply_batch(a, t, q)
    inv = batch.apply_inverse_batch(a, t, fwd)
    np.testing.assert_allclose(inv, q, atol=1e-9)
    r, tr = batch.least_squares_batch(s, b)
    inv_rigid = batch.apply_inverse_batch(r, tr, q, rigid=True)
    for k in range(len(s)):
        lin = registration.combinatorial(s[k], b[k]).mapping
        np.testing.assert_allclose(fwd[k], lin.apply(q[k]), atol=TOL)
        np.testing.assert_allclose(batch.apply_inverse_batch(a, t, q)[k], lin.apply_inverse(q[k]), atol=TOL)
        rig = registration.least_squares(s[k], b[k]).mapping
        np.testing.assert_allclose(inv_rigid[k], rig.apply_inverse(q[k]), atol=TOL)
    # shared (M, 3) points are broadcast to every trial
    np.testing.assert_allclose(batch.apply_batch(a, t, q[0]), batch.apply_batch(a, t, np.broadcast_to(q[0], q.shape)))


@pytest.mark.parametrize("k, power", [(1, 2.0), (3, 1.0), (4, 2.0), (4, 3.5), (12, 2.0), (50, 0.5)])
@pytest.mark.parametrize("planar", [False, True])
def test_idw_batch_equals_loop(k, power, planar):
    c = _cell(seed=21, trials=6, planar=planar)
    fid, q = c["fid_s"], c["query"].copy()
    rng = np.random.default_rng(3)
    corr = rng.normal(0, 0.5, fid.shape)
    q[:, 0] = fid[:, 3]  # exactly on a fiducial
    q[:, 1] = fid[:, 5] + 3e-10  # within EXACT_MM of one
    q[:, 2] = fid[:, 7] + 5e-9  # just outside EXACT_MM
    out = batch.idw_batch(fid, corr, q, k=k, power=power)
    for t in range(len(fid)):
        ref = interpolation.IDW(k=k, power=power).fit(fid[t], corr[t]).predict(q[t]).values
        np.testing.assert_allclose(out[t], ref, rtol=0, atol=TOL)
    np.testing.assert_array_equal(out[:, 0], corr[:, 3])


def test_idw_batch_query_on_fiducials_closer_than_exact_mm():
    """Two fiducials closer than EXACT_MM (not exactly equal, so that no query has an exact tie for its k-th
    neighbour, which IDW breaks arbitrarily) and a query on them: the mean of their corrections."""
    c = _cell(seed=23, trials=2, n_fid=8)
    fid, q = c["fid_s"].copy(), c["query"].copy()
    corr = np.random.default_rng(4).normal(0, 0.5, fid.shape)
    fid[1, 6] = fid[1, 7] + 4e-10
    q[1, 3] = fid[1, 7]
    out = batch.idw_batch(fid, corr, q, k=2, power=2.0)
    for t in range(2):
        ref = interpolation.IDW(k=2).fit(fid[t], corr[t]).predict(q[t]).values
        np.testing.assert_allclose(out[t], ref, rtol=0, atol=TOL)
    np.testing.assert_allclose(out[1, 3], corr[1, 6:8].mean(0), atol=1e-15)


def test_idw_batch_in_small_chunks(monkeypatch):
    monkeypatch.setattr(batch_checks, "_CHUNK_ELEMENTS", 50)
    c = _cell(seed=22, trials=7)
    corr = np.random.default_rng(0).normal(size=c["fid_s"].shape)
    out = batch.idw_batch(c["fid_s"], corr, c["query"][0])  # (M, 3) queries shared by the trials
    for t in range(7):
        ref = interpolation.IDW().fit(c["fid_s"][t], corr[t]).predict(c["query"][0]).values
        np.testing.assert_allclose(out[t], ref, rtol=0, atol=TOL)


# ------------------------------------------------------------------------------------------------------
# The whole chain, every registration x interpolation
# ------------------------------------------------------------------------------------------------------
REG_OPTIONS = {"annealing": {"iterations": 60}}


def _reference(reg_name, interp, c, k, seed, reg_options, interp_options):
    extra = {"seed": seed} if reg_name in ("annealing", "clustering") else {}
    reg = registration.register(reg_name, c["reg_s"][k], c["reg_b"][k], **reg_options, **extra)
    e = fiducial_corrections(reg.mapping, c["fid_s"][k], c["fid_b"][k])
    fitted = interpolation.make_interpolator(interp, **interp_options).fit(c["fid_s"][k], e)
    return correct_points(reg.mapping, fitted, c["query"][k]), e


@pytest.mark.parametrize("reg_name", REGS)
@pytest.mark.parametrize("interp", INTERPS)
def test_rrbc_batch_equals_loop_for_every_combination(reg_name, interp):
    c = _cell(seed=31, trials=2, planar=(interp == "tps"), n_reg=6, n_fid=10, n_q=7)
    seeds = np.array([4, 9])
    opts = REG_OPTIONS.get(reg_name, {})
    interp_options = {"k": 3, "power": 2.5} if interp == "idw" else {}
    out = batch.rrbc_batch(
        reg_name,
        interp,
        c["reg_s"],
        c["reg_b"],
        c["fid_s"],
        c["fid_b"],
        c["query"],
        seeds=seeds,
        registration_options=opts,
        hull="trial",
        **interp_options,
    )
    for k in range(2):
        ref, e = _reference(reg_name, interp, c, k, int(seeds[k]), opts, interp_options)
        np.testing.assert_allclose(out["robot_rigid"][k], ref.robot_rigid, rtol=0, atol=TOL)
        np.testing.assert_allclose(out["robot_rrbc"][k], ref.robot_rrbc, rtol=0, atol=TOL)
        np.testing.assert_allclose(out["corrections"][k], ref.correction, rtol=0, atol=TOL)
        np.testing.assert_allclose(out["fiducial_corrections"][k], e, rtol=0, atol=TOL)
        np.testing.assert_array_equal(out["extrapolated"][k], ref.extrapolated)


@pytest.mark.parametrize("reg_name", ["least-squares", "combinatorial", "clustering"])
def test_rrbc_batch_options_seeds_and_hull_modes(reg_name):
    c = _cell(seed=32, trials=3, n_reg=8)
    opts = {
        "least-squares": {"weights": np.arange(1.0, 9.0)},
        "combinatorial": {"average": "chordal"},
        "clustering": {"clusters": 3, "average": "chordal"},
    }[reg_name]
    args = (c["reg_s"], c["reg_b"], c["fid_s"], c["fid_b"], c["query"])
    out = batch.rrbc_batch(reg_name, "idw", *args, registration_options=opts)  # default seeds: k for trial k
    for k in range(3):
        ref, _ = _reference(reg_name, "idw", c, k, k, opts, {})
        np.testing.assert_allclose(out["robot_rrbc"][k], ref.robot_rrbc, rtol=0, atol=TOL)
    mean_flags, _ = interpolation.hull_flags(c["fid_s"].mean(0), c["query"].mean(0))
    np.testing.assert_array_equal(out["extrapolated"], mean_flags)
    assert out["extrapolated"].shape == (c["query"].shape[1],)
    assert batch.rrbc_batch(reg_name, "idw", *args, registration_options=opts, hull="none")["extrapolated"] is None
    if reg_name != "clustering":
        np.testing.assert_allclose(batch.apply_batch(out["matrix"], out["translation"], c["query"]), out["robot_rigid"])
    # queries shared by every trial, (M, 3), are broadcast
    shared = batch.rrbc_batch(reg_name, "idw", *args[:4], c["query"][0], registration_options=opts)
    full = batch.rrbc_batch(
        reg_name, "idw", *args[:4], np.broadcast_to(c["query"][0], c["query"].shape), registration_options=opts
    )
    np.testing.assert_array_equal(shared["robot_rrbc"], full["robot_rrbc"])


def test_rrbc_batch_without_fiducials_for_no_correction():
    c = _cell(seed=33, trials=3)
    empty = np.zeros((3, 0, 3))
    for reg_name in ("least-squares", "clustering"):
        out = batch.rrbc_batch(reg_name, "none", c["reg_s"], c["reg_b"], empty, empty, c["query"], hull="trial")
        np.testing.assert_array_equal(out["robot_rrbc"], out["robot_rigid"])
        for k in range(3):
            flags, _ = interpolation.hull_flags(c["reg_s"][k], c["query"][k])
            np.testing.assert_array_equal(out["extrapolated"][k], flags)
    with pytest.raises(InputError, match="no fiducials"):
        batch.rrbc_batch("least-squares", "idw", c["reg_s"], c["reg_b"], empty, empty, c["query"])


# ------------------------------------------------------------------------------------------------------
# Input validation
# ------------------------------------------------------------------------------------------------------
def test_degenerate_trials_are_refused_with_the_trial_named():
    c = _cell(seed=41, trials=4, n_reg=4)
    s, b = c["reg_s"].copy(), c["reg_b"]
    s[2, 1] = s[2, 0] + 1e-4
    with pytest.raises(InputError, match="trial 2: .*coincide"):
        batch.least_squares_batch(s, b)
    s = c["reg_s"].copy()
    s[3] = np.array([[0.0, 0, 0], [100, 0, 0], [200, 0.1, 0], [300, 0, 0]])
    with pytest.raises(InputError, match="trial 3: .*collinear"):
        batch.combinatorial_batch(s, b)
    s = c["reg_s"].copy()
    s[1, 2, 0] = np.nan
    with pytest.raises(InputError, match="trial 1: .*non-finite"):
        batch.three_point_batch(s, b)
    with pytest.raises(InputError, match="at least 3"):
        batch.least_squares_batch(s[:, :2], b[:, :2])
    with pytest.raises(InputError, match="pair up"):
        batch.least_squares_batch(c["reg_s"], b[:, :3])
    with pytest.raises(InputError, match="T x N x 3"):
        batch.least_squares_batch(c["reg_s"][0], b[0])
    # degeneracy_ratio 0 keeps an exactly collinear triple: NaN frames, refused like the core's _finish does
    p = np.array([[0.0, 0, 0], [100, 0, 0], [200, 0, 0], [0, 100, 0], [0, 0, 100]])
    with pytest.raises(InputError, match="numerically degenerate"), np.errstate(invalid="ignore"):
        registration.combinatorial(p, p + 1, degeneracy_ratio=0)
    with pytest.raises(InputError, match="trial 0: .*numerically degenerate"):
        batch.combinatorial_batch(np.stack([p, p]), np.stack([p, p]) + 1, degeneracy_ratio=0)


def test_bad_options_are_refused():
    c = _cell(seed=42, trials=3)
    s, b = c["reg_s"], c["reg_b"]
    args = (s, b, c["fid_s"], c["fid_b"], c["query"])
    with pytest.raises(InputError, match="weights"):
        batch.least_squares_batch(s, b, weights=[1.0, 0, 0, 0, 0, 0, 1])
    with pytest.raises(InputError, match="seeds"):
        batch.annealing_batch(s, b, seeds=[1, 2])
    with pytest.raises(InputError, match="seeds"):
        batch.annealing_batch(s, b, seeds=[1, -2, 3])
    with pytest.raises(InputError, match="iterations"):
        batch.annealing_batch(s, b, iterations=0)
    with pytest.raises(InputError, match="averaging"):
        batch.combinatorial_batch(s, b, average="median")
    with pytest.raises(InputError, match="degeneracy_ratio"):
        batch.combinatorial_batch(s, b, degeneracy_ratio="high")
    with pytest.raises(InputError, match="numbers"):
        batch.least_squares_batch([[["a", "b", "c"]] * 3], [[["a", "b", "c"]] * 3])
    with pytest.raises(InputError, match="idw k"):
        batch.idw_batch(c["fid_s"], c["fid_s"], c["query"], k=0)
    with pytest.raises(InputError, match="unknown registration"):
        batch.rrbc_batch("icp", "idw", *args)
    with pytest.raises(InputError, match="unknown interpolation"):
        batch.rrbc_batch("least-squares", "kriging", *args)
    with pytest.raises(InputError, match="does not take"):
        batch.rrbc_batch("least-squares", "idw", *args, smoothing=1.0)
    with pytest.raises(InputError, match="does not take"):
        batch.rrbc_batch("three-point", "idw", *args, registration_options={"weights": None})
    with pytest.raises(InputError, match="hull"):
        batch.rrbc_batch("least-squares", "idw", *args, hull="convex")
    with pytest.raises(InputError, match="trials"):
        batch.rrbc_batch("least-squares", "idw", s, b, c["fid_s"][:2], c["fid_b"][:2], c["query"])


def test_subset_screen_decides_like_the_core_svd():
    """The closed-form screen for collinear triples must give exactly the core's decision
    (collinear_ratio_batch >= ratio), including triples within rounding of the threshold."""
    rng = np.random.default_rng(8)
    k = 4000
    base = rng.uniform(-500, 500, (k, 3, 3)) + rng.uniform(-2000, 2000, (k, 1, 3))
    c = base - base.mean(axis=1, keepdims=True)
    u, sv, vt = np.linalg.svd(c, full_matrices=False)
    target = 0.05 * (1 + rng.choice([0.0, 1e-14, -1e-14, 1e-4, -1e-4, 5e-3, -5e-3, 0.5, -0.5], k))
    sv[:, 1] = sv[:, 0] * target  # set sigma2/sigma1 at (or within rounding of) the threshold
    triples = np.einsum("kij,kj,kjl->kil", u, sv, vt) + base.mean(axis=1, keepdims=True)
    expected = points_mod.collinear_ratio_batch(triples) >= 0.05
    assert 0 < expected.sum() < k
    np.testing.assert_array_equal(batch_registration._subset_ok(triples, 0.05), expected)


def test_registration_points_near_the_collinearity_limit():
    """sigma2/sigma1 slightly above COLLINEAR_RATIO passes (as in the core), slightly below is refused."""
    rng = np.random.default_rng(9)
    line = np.c_[np.linspace(0, 600, 5), np.zeros(5), np.zeros(5)]
    true = RigidTransform(_rotation(rng, "random"), [1, 2, 3])
    for ratio, ok in ((0.0105, True), (0.0095, False)):
        pts = line.copy()
        pts[[1, 3], 1] = [1.0, -1.0]
        pts[:, 1] *= ratio / points_mod.spread_ratios(pts)[0]
        s = np.broadcast_to(pts, (3, 5, 3)).copy()
        b = true.apply(pts)[None] + rng.normal(0, 1e-3, (3, 5, 3))
        if ok:
            r, t = batch.least_squares_batch(s, b)
            for k in range(3):
                _assert_same(registration.least_squares(s[k], b[k]).mapping, r[k], t[k])
        else:
            with pytest.raises(InputError, match="trial 0: .*collinear"):
                batch.least_squares_batch(s, b)


# ------------------------------------------------------------------------------------------------------
# The compiled least-squares + IDW kernel (rrbc_core/simulation/compiled.py): what rrbc_batch runs for the default chain
# ------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("layout", LAYOUTS)
@pytest.mark.parametrize("k, power", [(4, 2.0), (3, 2.5), (1, 1.0), (50, 0.5)])
def test_compiled_least_squares_idw_equals_the_core_over_many_trials(layout, k, power):
    """Many trials (the kernel warm-starts each trial's 3x3 SVD from the previous one), coplanar registration
    points (rank-2 H), near half-turn rotations, 3 registration points, k beyond the fiducial count."""
    c = _cell(trials=60, **layout)
    out = batch.rrbc_batch(
        "least-squares",
        "idw",
        c["reg_s"],
        c["reg_b"],
        c["fid_s"],
        c["fid_b"],
        c["query"],
        hull="trial",
        k=k,
        power=power,
    )
    for t in range(0, 60, 7):
        ref, e = _reference("least-squares", "idw", c, t, 0, {}, {"k": k, "power": power})
        np.testing.assert_allclose(out["robot_rigid"][t], ref.robot_rigid, rtol=0, atol=TOL)
        np.testing.assert_allclose(out["robot_rrbc"][t], ref.robot_rrbc, rtol=0, atol=TOL)
        np.testing.assert_allclose(out["corrections"][t], ref.correction, rtol=0, atol=TOL)
        np.testing.assert_allclose(out["fiducial_corrections"][t], e, rtol=0, atol=TOL)
        np.testing.assert_array_equal(out["extrapolated"][t], ref.extrapolated)
        reg = registration.least_squares(c["reg_s"][t], c["reg_b"][t])
        _assert_same(reg.mapping, out["matrix"][t], out["translation"][t])
    mean = batch.rrbc_batch(
        "least-squares", "idw", c["reg_s"], c["reg_b"], c["fid_s"], c["fid_b"], c["query"], k=k, power=power
    )
    np.testing.assert_array_equal(
        mean["extrapolated"], interpolation.hull_flags(c["fid_s"].mean(0), c["query"].mean(0))[0]
    )


def test_compiled_kernel_takes_the_exact_branch_on_fiducials():
    """A query on a fiducial takes its correction; on two coincident fiducials, their mean (as the core)."""
    c = _cell(seed=77, trials=3, n_fid=8)
    fid_s, fid_b = c["fid_s"].copy(), c["fid_b"].copy()
    fid_s[:, 1], fid_b[:, 1] = fid_s[:, 0], fid_b[:, 0] + 0.05  # two fiducials at one place, different readings
    q = c["query"].copy()
    q[:, 0], q[:, 1] = fid_s[:, 0], fid_s[:, 3]
    out = batch.rrbc_batch("least-squares", "idw", c["reg_s"], c["reg_b"], fid_s, fid_b, q, hull="none")
    for t in range(3):
        cc = dict(c, fid_s=fid_s, fid_b=fid_b, query=q)
        ref, e = _reference("least-squares", "idw", cc, t, 0, {}, {})
        np.testing.assert_allclose(out["corrections"][t], ref.correction, rtol=0, atol=TOL)
        np.testing.assert_allclose(out["corrections"][t, 0], e[:2].mean(0), rtol=0, atol=TOL)
        np.testing.assert_allclose(out["corrections"][t, 1], e[3], rtol=0, atol=TOL)


@pytest.mark.parametrize("which", ["reg_s", "reg_b", "fid_s", "fid_b", "query"])
def test_compiled_kernel_inputs_are_checked_like_the_general_path(which):
    c = _cell(seed=78, trials=6, n_reg=5)
    bad = {key: c[key].copy() for key in ("reg_s", "reg_b", "fid_s", "fid_b", "query")}
    bad[which][4, 1, 2] = np.inf
    with pytest.raises(InputError, match="trial 4: .*non-finite"):
        batch.rrbc_batch("least-squares", "idw", *bad.values())
    bad = {key: c[key].copy() for key in ("reg_s", "reg_b", "fid_s", "fid_b", "query")}
    if which in ("reg_s", "reg_b"):
        bad[which][3] = np.array([[0.0, 0, 0], [100, 0, 0], [200, 0.1, 0], [300, 0, 0], [400, 0, 0.1]])
        with pytest.raises(InputError, match="trial 3: .*collinear"):
            batch.rrbc_batch("least-squares", "idw", *bad.values())
        bad[which][3] = c[which][3]
        bad[which][5, 2] = bad[which][5, 0] + 1e-4
        with pytest.raises(InputError, match="trial 5: .*coincide"):
            batch.rrbc_batch("least-squares", "idw", *bad.values())


def test_compiled_kabsch_equals_the_core_on_aligned_and_random_frames():
    """Frames aligned with the axes (H diagonal: the SVD's columns come out of order and are sorted, so V turns
    improper) and random ones, spreads of every order: the kernel's rotation is the core's."""
    rng = np.random.default_rng(5)
    sets = []
    for spreads in ([1.0, 2.0, 3.0], [3.0, 2.0, 1.0], [2.0, 3.0, 1.0], [1.0, 3.0, 0.0], [5.0, 5.0, 1.0]):
        sets.append((rng.normal(size=(9, 3)) * np.array(spreads) * 100.0, np.eye(3)))
    for _ in range(40):
        sets.append(
            (
                rng.normal(size=(9, 3)) * rng.uniform(0.05, 3.0, 3) * 100.0,
                Rotation.random(random_state=rng.integers(2**31)).as_matrix(),
            )
        )
    for p, rot in sets:
        s = p[None] + rng.normal(0, 0.01, (4,) + p.shape)
        b = s @ rot.T + [10.0, -20.0, 30.0] + rng.normal(0, 0.01, s.shape)
        fid = s[:, :4] + 1.0
        out = batch.rrbc_batch("least-squares", "idw", s, b, fid, fid @ rot.T, s[:, 4:], hull="none")
        for t in range(4):
            _assert_same(registration.least_squares(s[t], b[t]).mapping, out["matrix"][t], out["translation"][t])
