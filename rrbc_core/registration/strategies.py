"""Registration strategies: from paired sensor/robot points to a sensor→robot mapping.

Every strategy has the same call shape, `strategy(p_sensor, b_robot, **options) -> Registration`, where
`p_sensor` and `b_robot` are (N, 3) arrays of the same physical points measured in each frame (mm), and the
returned `Registration` holds the mapping `T_robot_sensor` (`b_robot ≈ T_robot_sensor.apply(p_sensor)`) as
`mapping`, and the fit residuals `b_robot - mapping.apply(p_sensor)` (robot frame, mm). Names of frames:
docs/architecture.md ("Frames in names"); inside a function `s` and `b` are the checked sensor and robot points.

Mappings:
- `RigidTransform` (least squares, three-point, combinatorial with chordal averaging, annealing from a rigid
  start): robot = R @ sensor + t.
- `LinearMap` (combinatorial with element-wise averaging, as published by Van Wyk & Marvel 2018, and
  least squares with a similarity scale): robot = A @ sensor + t where A is close to, but not exactly, a
  rotation. `apply_inverse` solves A x = robot - t.
- `PiecewiseMap` (clustering): one mapping per cluster kernel; a sensor point is mapped by the piece of the
  nearest kernel. It is *not* one rigid transform: `piecewise` is True, and the pieces are exposed.

Degenerate input (fewer than 3 points, coincident points, (nearly) collinear points; see geometry.py) raises
`InputError`; no strategy returns a reflection or NaN.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from itertools import combinations
from typing import ClassVar, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike

from rrbc_core.errors import InputError
from rrbc_core.geometry import points as geometry
from rrbc_core.geometry.transforms import (
    RigidTransform,
    chordal_mean,
    map_points,
    project_to_so3,
    rotation_from_euler_zyx,
)


# ------------------------------------------------------------------------------------------------------
# Mappings
# ------------------------------------------------------------------------------------------------------
@runtime_checkable
class SensorToRobot(Protocol):
    """What every sensor→robot mapping offers (`RigidTransform`, `LinearMap`, `PiecewiseMap`): robot =
    apply(sensor) and its inverse, points (..., 3) mm; a rotation and translation for display (a summary for a
    piecewise map); its JSON (`as_dict`); and whether it is one map everywhere (`piecewise` False) or one per
    region of the sensor frame (True: `PiecewiseMap.piece_of` says which)."""

    piecewise: ClassVar[bool]

    def apply(self, points: ArrayLike) -> np.ndarray: ...

    def apply_inverse(self, points: ArrayLike) -> np.ndarray: ...

    @property
    def rotation(self) -> np.ndarray: ...

    @property
    def translation(self) -> np.ndarray: ...

    def as_dict(self) -> dict: ...


@dataclass(frozen=True, eq=False)
class LinearMap:
    """robot = matrix @ sensor + translation, with `matrix` near a rotation (element-wise averages) or a
    scaled rotation (similarity). Units mm."""

    matrix: np.ndarray
    translation: np.ndarray
    piecewise: ClassVar[bool] = False

    def apply(self, points) -> np.ndarray:
        p = np.asarray(points, dtype=float)
        return map_points(p, self.matrix, self.translation)

    def apply_inverse(self, points) -> np.ndarray:
        q = np.asarray(points, dtype=float) - self.translation
        return np.linalg.solve(self.matrix, q.reshape(-1, 3).T).T.reshape(q.shape)

    @property
    def rotation(self) -> np.ndarray:
        """The nearest rotation to `matrix` (for display); the map itself uses `matrix`."""
        return project_to_so3(self.matrix)

    def as_dict(self) -> dict:
        return {"rotation": self.matrix.tolist(), "translation": self.translation.tolist()}


@dataclass(frozen=True, eq=False)
class PiecewiseMap:
    """One mapping per kernel (sensor frame, mm). A point uses the piece whose kernel is nearest to it.

    `apply(points)` picks pieces by the sensor points themselves; `apply_inverse(robot, pieces)` needs the
    piece index per point (from `piece_of(sensor_points)`), because the piece is defined in the sensor frame;
    without it, each robot point uses the piece whose kernel image is nearest in the robot frame.
    """

    kernels: np.ndarray  # (K, 3) sensor frame
    pieces: tuple  # K mappings
    piecewise: ClassVar[bool] = True

    def piece_of(self, sensor_points) -> np.ndarray:
        p = np.atleast_2d(np.asarray(sensor_points, dtype=float))
        d = np.linalg.norm(p[:, None, :] - self.kernels[None, :, :], axis=-1)
        return np.argmin(d, axis=1)

    def apply(self, points, pieces=None) -> np.ndarray:
        p = np.asarray(points, dtype=float)
        flat = np.atleast_2d(p)
        idx = self.piece_of(flat) if pieces is None else np.asarray(pieces)
        out = np.empty_like(flat)
        for k, piece in enumerate(self.pieces):
            sel = idx == k
            if np.any(sel):
                out[sel] = piece.apply(flat[sel])
        return out.reshape(p.shape)

    def apply_inverse(self, points, pieces=None) -> np.ndarray:
        q = np.asarray(points, dtype=float)
        flat = np.atleast_2d(q)
        if pieces is None:
            images = np.array([pc.apply(k) for pc, k in zip(self.pieces, self.kernels)])
            idx = np.argmin(np.linalg.norm(flat[:, None, :] - images[None], axis=-1), axis=1)
        else:
            idx = np.asarray(pieces)
        out = np.empty_like(flat)
        for k, piece in enumerate(self.pieces):
            sel = idx == k
            if np.any(sel):
                out[sel] = piece.apply_inverse(flat[sel])
        return out.reshape(q.shape)

    @property
    def rotation(self) -> np.ndarray:
        """Chordal mean of the pieces' rotations (for a one-line summary only)."""
        return chordal_mean([pc.rotation for pc in self.pieces])

    @property
    def translation(self) -> np.ndarray:
        """Mean translation of the pieces (for a one-line summary only)."""
        return np.mean([pc.translation for pc in self.pieces], axis=0)

    def as_dict(self) -> dict:
        return {
            "rotation": self.rotation.tolist(),
            "translation": self.translation.tolist(),
            "piecewise": True,
            "pieces": [{"kernel": k.tolist(), **pc.as_dict()} for k, pc in zip(self.kernels, self.pieces)],
        }


@dataclass(frozen=True, eq=False)
class Registration:
    """Result of a registration strategy.

    mapping: sensor→robot mapping (RigidTransform, LinearMap or PiecewiseMap).
    residuals: (N, 3) robot − mapping.apply(sensor) at the registration points, robot frame, mm.
    fre_rms_mm: RMS of the residual norms (FRE), mm.
    details: strategy-specific facts (subsets used, cost history, clusters, scale...).
    """

    method: str
    mapping: SensorToRobot
    residuals: np.ndarray
    fre_rms_mm: float
    details: dict = field(default_factory=dict)

    @property
    def piecewise(self) -> bool:
        return bool(self.mapping.piecewise)


def _finish(method, T_robot_sensor, p_sensor, b_robot, **details) -> Registration:
    res = b_robot - T_robot_sensor.apply(p_sensor)
    if not np.all(np.isfinite(res)):
        raise InputError(f"{method}: the registration is numerically degenerate for these points")
    fre = float(np.sqrt(np.mean(np.sum(res**2, axis=1))))
    return Registration(method, T_robot_sensor, res, fre, details)


def _check_pair(p_sensor, b_robot, minimum=3):
    s = geometry.check_registration_points(p_sensor, "sensor registration points", minimum)
    b = geometry.check_registration_points(b_robot, "robot registration points", minimum)
    if s.shape != b.shape:
        raise InputError(f"sensor and robot registration points must pair up: {len(s)} sensor vs {len(b)} robot points")
    return s, b


# ------------------------------------------------------------------------------------------------------
# Least squares (Arun/Kabsch/Umeyama)
# ------------------------------------------------------------------------------------------------------
def kabsch(p_sensor, b_robot, weights=None, with_scale=False):
    """Weighted Kabsch/Umeyama. Returns (R, t, scale). Theory docs/theory.md §1.2 and §1.4."""
    w = np.ones(len(p_sensor)) if weights is None else np.asarray(weights, dtype=float)
    w = w / w.sum()
    ps = w @ p_sensor
    pb = w @ b_robot
    sc = p_sensor - ps
    bc = b_robot - pb
    h = (sc * w[:, None]).T @ bc  # H = Σ w p' q'^T
    u, s, vt = np.linalg.svd(h)
    d = np.ones(3)
    d[2] = 1.0 if np.linalg.det(vt.T @ u.T) >= 0 else -1.0
    rot = vt.T @ np.diag(d) @ u.T
    scale = 1.0
    if with_scale:
        var = np.sum(w * np.sum(sc**2, axis=1))
        scale = float(np.sum(s * d) / var)
    t = pb - scale * rot @ ps
    return rot, t, scale


def least_squares(p_sensor, b_robot, weights=None, with_scale: bool = False) -> Registration:
    """Least-squares rigid registration (Kabsch/Umeyama with the reflection fix).

    weights: optional (N,) non-negative per-point weights (ideally 1/σ_i²).
    with_scale: also fit a uniform scale (similarity transform, Umeyama's least-squares scale); the mapping
    is then a LinearMap (scale·R, t) and details['scale'] holds the scale. For diagnostics, not registration.
    """
    s, b = _check_pair(p_sensor, b_robot)
    if weights is not None:
        w = np.asarray(weights, dtype=float)
        if w.shape != (len(s),) or not np.all(np.isfinite(w)) or np.any(w < 0) or np.count_nonzero(w) < 3:
            raise InputError("weights must be one finite non-negative number per point, at least 3 positive")
    rot, t, scale = kabsch(s, b, weights, with_scale)
    if with_scale:
        return _finish("least-squares", LinearMap(scale * rot, t), s, b, scale=scale, rotation=rot)
    return _finish("least-squares", RigidTransform(project_to_so3(rot), t), s, b)


# ------------------------------------------------------------------------------------------------------
# Three-point frame (Van Wyk & Marvel 2018, eqs. 1-5)
# ------------------------------------------------------------------------------------------------------
def _frames(p1, p2, p3):
    """Homogeneous frames H_O (…, 4, 4) with origin p1, x̂ along p1→p2, ŷ = x̂ × (p3−p1)/‖·‖, ẑ = x̂ × ŷ
    (Van Wyk eqs. 1–4; the frame is right-handed: ẑ = x̂ × ŷ). Vectorised over leading axes."""
    x = p2 - p1
    x = x / np.linalg.norm(x, axis=-1, keepdims=True)
    y = np.cross(x, p3 - p1)
    y = y / np.linalg.norm(y, axis=-1, keepdims=True)
    z = np.cross(x, y)
    h = np.zeros(p1.shape[:-1] + (4, 4))
    h[..., :3, 0] = x
    h[..., :3, 1] = y
    h[..., :3, 2] = z
    h[..., :3, 3] = p1
    h[..., 3, 3] = 1.0
    return h


def three_point_matrices(p_sensor_triples, b_robot_triples) -> np.ndarray:
    """4x4 registrations H = H_O(robot) · H_O(sensor)⁻¹ for stacks of triples (K, 3, 3) (eq. 5)."""
    hs = _frames(p_sensor_triples[:, 0], p_sensor_triples[:, 1], p_sensor_triples[:, 2])
    hb = _frames(b_robot_triples[:, 0], b_robot_triples[:, 1], b_robot_triples[:, 2])
    hs_inv = np.zeros_like(hs)
    rt = np.swapaxes(hs[:, :3, :3], -1, -2)
    hs_inv[:, :3, :3] = rt
    hs_inv[:, :3, 3] = -np.einsum("kij,kj->ki", rt, hs[:, :3, 3])
    hs_inv[:, 3, 3] = 1.0
    return hb @ hs_inv


def three_point(p_sensor, b_robot) -> Registration:
    """3-point frame registration (Van Wyk & Marvel 2018, eqs. 1–5) on the FIRST three points.

    Point 1 is the frame origin and 1→2 the x-axis: all the error lands on point 1 and that direction
    (it is not a least-squares fit). Extra points are ignored for the fit but still get residuals.
    """
    s, b = _check_pair(p_sensor, b_robot)
    geometry.check_registration_points(s[:3], "the first three sensor registration points")
    geometry.check_registration_points(b[:3], "the first three robot registration points")
    h = three_point_matrices(s[None, :3], b[None, :3])[0]
    return _finish("three-point", RigidTransform(project_to_so3(h[:3, :3]), h[:3, 3]), s, b, points_used=[0, 1, 2])


# ------------------------------------------------------------------------------------------------------
# Combinatorial averaging (eqs. 6-7)
# ------------------------------------------------------------------------------------------------------
#: Most registration points the subset-averaging strategies (combinatorial, annealing's start, clustering's
#: pieces) accept: they register every 3-point subset, C(N, 3) of them (41 664 at 64 points), which grows
#: as N³ (26 million subsets and out of memory near N = 540). Least squares uses any number of points.
MAX_SUBSET_POINTS = 64


def check_subset_count(n: int, method: str = "combinatorial") -> None:
    """Refuse (InputError) more than MAX_SUBSET_POINTS registration points for a subset-averaging strategy."""
    if n > MAX_SUBSET_POINTS:
        raise InputError(
            f"{method} registration averages the registrations of every 3-point subset: {n} registration points "
            f"give {math.comb(n, 3):,} subsets; it accepts at most {MAX_SUBSET_POINTS} points "
            f"({math.comb(MAX_SUBSET_POINTS, 3):,} subsets). Use least-squares, which uses every point, or fewer "
            "registration points"
        )


def _subset_registrations(s, b, degeneracy_ratio, method: str = "combinatorial"):
    check_subset_count(len(s), method)
    combos = np.array(list(combinations(range(len(s)), 3)))
    st, bt = s[combos], b[combos]
    ok = (geometry.collinear_ratio_batch(st) >= degeneracy_ratio) & (
        geometry.collinear_ratio_batch(bt) >= degeneracy_ratio
    )
    if not np.any(ok):
        raise InputError(
            f"combinatorial registration: every 3-point subset is nearly collinear "
            f"(sigma2/sigma1 < {degeneracy_ratio}); spread the registration points"
        )
    return combos[ok], three_point_matrices(st[ok], bt[ok]), int(np.count_nonzero(~ok))


def _average(mats, average, origin):
    if average == "elementwise":
        m = mats.mean(axis=0)
        return LinearMap(m[:3, :3], m[:3, 3])
    if average == "chordal":
        rot = chordal_mean(mats[:, :3, :3])
        images = np.einsum("kij,j->ki", mats[:, :3, :3], origin) + mats[:, :3, 3]
        return RigidTransform(rot, images.mean(axis=0) - rot @ origin)
    raise InputError(f"unknown averaging '{average}': use 'elementwise' (as published) or 'chordal'")


def combinatorial(
    p_sensor, b_robot, average: str = "elementwise", degeneracy_ratio: float = geometry.SUBSET_DEGENERACY_RATIO
) -> Registration:
    """Average of the 3-point frame registrations of every non-degenerate 3-point subset (eqs. 6–7).

    average='elementwise' (as published): the 4x4 matrices are averaged element by element; the linear part
    is then not exactly a rotation, and the mapping is a LinearMap that uses it as is.
    average='chordal': rotations averaged by the chordal mean (a proper rotation), translations averaged so
    that the mean is exact at the registration points' centroid (docs/theory.md §3.2).
    Subsets whose sigma2/sigma1 (in either frame) is below `degeneracy_ratio` are rejected (default
    geometry.SUBSET_DEGENERACY_RATIO = 0.05). Within a subset, the lowest-index point is the frame origin.
    """
    s, b = _check_pair(p_sensor, b_robot)
    combos, mats, rejected = _subset_registrations(s, b, degeneracy_ratio)
    T_robot_sensor = _average(mats, average, s.mean(axis=0))
    return _finish(
        "combinatorial", T_robot_sensor, s, b, average=average, subsets_used=len(combos), subsets_rejected=rejected
    )


# ------------------------------------------------------------------------------------------------------
# Simulated annealing refinement (eqs. 8-15)
# ------------------------------------------------------------------------------------------------------
def _modifier(theta) -> RigidTransform:
    x, y, z, a, b, g = theta
    return RigidTransform(rotation_from_euler_zyx(a, b, g), np.array([x, y, z], float))


def _compose_modifier(mod: RigidTransform, T_robot_sensor):
    """mod ∘ mapping (the modifier acts in the robot frame after the initial registration)."""
    if isinstance(T_robot_sensor, RigidTransform):
        return mod.compose(T_robot_sensor)
    return LinearMap(mod.rotation @ T_robot_sensor.matrix, mod.rotation @ T_robot_sensor.translation + mod.translation)


def annealing(
    p_sensor,
    b_robot,
    initial: Registration | None = None,
    seed: int = 0,
    iterations: int = 5000,
    cooling_c: float = 2.0,
    polish: bool = False,
) -> Registration:
    """Simulated-annealing refinement as published (Van Wyk & Marvel 2018, eqs. 8–15).

    A modifier Θ = (x, y, z, α, β, γ) (mm, rad; Euler Z-Y-X) is applied after the initial registration
    (robot = H(Θ) · H_init(sensor)); the cost is Σ‖E_i‖² (mm², eq. 9); a neighbour Θ' = Θ + N(0, diag(step²))
    is accepted if it lowers the cost or with probability exp(−Δ/T_τ), T_τ = 1/(C ln τ) with C = 2, τ = 2, 3, ….
    The best Θ seen is returned. Proposal steps (not given in the paper; our choice): translation step =
    FRE_init/4 per axis, angular step = FRE_init/(4·RMS radius of the points) — so the search explores the
    scale of the initial misfit. Note: with the cost in mm² the published schedule keeps T_τ far above typical
    cost changes, so the search is close to a random walk with best-so-far; `polish=True` (not published)
    finishes with scipy's Nelder–Mead from the best Θ.
    initial: the registration to refine; default `combinatorial` (element-wise), which for 3 points is the
    3-point frame method. Seeded: same seed, same result.
    """
    s, b = _check_pair(p_sensor, b_robot)
    if iterations < 1 or cooling_c <= 0:
        raise InputError("annealing needs iterations >= 1 and cooling constant C > 0")
    if initial is None:
        check_subset_count(len(s), "annealing (from the combinatorial average)")
    init = initial if initial is not None else combinatorial(s, b)
    mapped = init.mapping.apply(s)
    rng = np.random.default_rng(seed)

    def cost(theta):
        mod = _modifier(theta)
        return float(np.sum((b - mod.apply(mapped)) ** 2))

    radius = float(np.sqrt(np.mean(np.sum((s - s.mean(0)) ** 2, axis=1))))
    fre0 = max(init.fre_rms_mm, 1e-6)
    step = np.array([fre0 / 4] * 3 + [fre0 / (4 * radius)] * 3)
    theta = np.zeros(6)
    c_cur = cost(theta)
    best, c_best = theta.copy(), c_cur
    c0 = c_cur
    steps = rng.normal(size=(iterations, 6)) * step
    uniforms = rng.random(iterations)
    accepted = 0
    for k in range(iterations):
        tau = k + 2
        temp = 1.0 / (cooling_c * np.log(tau))
        cand = theta + steps[k]
        c_new = cost(cand)
        delta = c_new - c_cur
        if delta < 0 or uniforms[k] < np.exp(-delta / temp):
            theta, c_cur = cand, c_new
            accepted += 1
            if c_cur < c_best:
                best, c_best = theta.copy(), c_cur
    if polish:
        from scipy.optimize import minimize

        res = minimize(cost, best, method="Nelder-Mead", options={"xatol": 1e-10, "fatol": 1e-12, "maxiter": 4000})
        if res.fun < c_best:
            best, c_best = res.x, float(res.fun)
    T_robot_sensor = _compose_modifier(_modifier(best), init.mapping)
    return _finish(
        "annealing",
        T_robot_sensor,
        s,
        b,
        initial=init.method,
        theta=best.tolist(),
        cost_initial_mm2=c0,
        cost_final_mm2=c_best,
        accepted=accepted,
        seed=seed,
    )


# ------------------------------------------------------------------------------------------------------
# Clustering (eqs. 16-17)
# ------------------------------------------------------------------------------------------------------
def kmeans(points, k: int, seed: int = 0, iterations: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """Seeded k-means (k-means++ start, Lloyd iterations). Returns (kernels (k,3), labels (N,))."""
    p = np.asarray(points, dtype=float)
    rng = np.random.default_rng(seed)
    centres = [p[rng.integers(len(p))]]
    for _ in range(1, k):
        d2 = np.min(np.sum((p[:, None] - np.array(centres)[None]) ** 2, axis=-1), axis=1)
        probs = d2 / d2.sum() if d2.sum() > 0 else np.full(len(p), 1 / len(p))
        centres.append(p[rng.choice(len(p), p=probs)])
    c = np.array(centres)
    labels = np.zeros(len(p), dtype=int)
    for _ in range(iterations):
        labels = np.argmin(np.sum((p[:, None] - c[None]) ** 2, axis=-1), axis=1)
        new = np.array([p[labels == j].mean(0) if np.any(labels == j) else c[j] for j in range(k)])
        if np.allclose(new, c):
            break
        c = new
    return c, labels


def clustering(p_sensor, b_robot, clusters: int = 2, seed: int = 0, average: str = "elementwise") -> Registration:
    """Clustered registration (our reading of Van Wyk & Marvel 2018, eqs. 16–17): piecewise, not rigid.

    1. k-means (seeded) on the sensor registration points gives `clusters` kernels.
    2. Each cluster's point set is its members, plus the registration points nearest its kernel until it has
       at least 3 points that are not nearly collinear (with 4 points and 2 clusters, each cluster has 2
       members and borrows its nearest neighbour).
    3. Each cluster's registration is the combinatorial average of the 3-point frame registrations of its
       set (`average` as in `combinatorial`), rooted at its kernel: the averaged translation makes the
       mean exact at the kernel.
    4. A query point uses the registration of the nearest kernel (sensor frame).
    The paper's text gives steps 1 and 4; steps 2–3 are the project's stated assumptions.
    """
    s, b = _check_pair(p_sensor, b_robot)
    kernels, labels, members = clustering_sets(s, clusters, seed)
    pieces = []
    for j, chosen in enumerate(members):
        _, mats, _ = _subset_registrations(s[chosen], b[chosen], geometry.SUBSET_DEGENERACY_RATIO, "clustering")
        pieces.append(_average_rooted(mats, average, kernels[j]))
    T_robot_sensor = PiecewiseMap(kernels, tuple(pieces))
    return _finish("clustering", T_robot_sensor, s, b, clusters=clusters, members=members, labels=labels.tolist())


def clustering_sets(s: np.ndarray, clusters: int, seed: int) -> tuple[np.ndarray, np.ndarray, list[list[int]]]:
    """`clustering`'s steps 1 and 2, which depend on the sensor points s (N, 3) alone: the kernels (K, 3) sensor
    frame, each point's k-means label (N,) and each cluster's point set (indices, sorted)."""
    if not 1 <= clusters <= len(s):
        raise InputError(f"clustering needs 1 <= clusters <= number of registration points ({len(s)})")
    kernels, labels = kmeans(s, clusters, seed)
    members = []
    for j in range(clusters):
        order = np.argsort(np.linalg.norm(s - kernels[j], axis=1), kind="stable")
        chosen = [int(i) for i in np.flatnonzero(labels == j)]
        for i in order:
            if len(chosen) >= 3 and geometry.spread_ratios(s[chosen])[0] >= geometry.SUBSET_DEGENERACY_RATIO:
                break
            if i not in chosen:
                chosen.append(int(i))
        members.append(sorted(chosen))
    return kernels, labels, members


def _average_rooted(mats, average, kernel):
    """Average rooted at `kernel`: the translation makes the averaged map exact at the kernel."""
    if average == "elementwise":
        m = mats.mean(axis=0)
        images = np.einsum("kij,j->ki", mats[:, :3, :3], kernel) + mats[:, :3, 3]
        return LinearMap(m[:3, :3], images.mean(axis=0) - m[:3, :3] @ kernel)
    return _average(mats, average, kernel)
