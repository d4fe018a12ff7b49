"""Simulating the Van Wyk & Marvel (2018) breadboard experiment under candidate error models.

What is simulated (facts: `reference_data`, docs/reference/vanwyk2018.md): 16 test sites on one breadboard plate,
frame N = the plate frame. Seven registration methods (Table II order) map N to the robot frame; each is
followed by 80 check measurements (16 sites x 5 repetitions, the count Table I implies), and the translation
error e = |M⁻¹(robot reading) − hole| (mm, frame N) is recorded. The published statistics of those 80 errors
(mean, variance, max, r with distance from N's origin, KS p against the previous row, peg success) are
computed per simulated experiment.

Readings. A robot reading of hole j is  T_true(h_j) + δ  (robot frame, mm), where T_true is the layout's
N → robot transform and δ = Σ_c w_c · g_c is a weighted sum of unit PERTURBATION COMPONENTS (below). Every
component has its own seeded random stream, so two models that share a component share its draws (common
random numbers) and differences between models are not Monte Carlo noise.

Homogeneity. Every method's error is (to first order in δ / plate size, < 0.5 %) homogeneous of degree 1 in
the perturbation: scaling all weights by ρ scales every error by ρ. The simulated annealing nearly keeps this
because its cost is evaluated in m² (assumption: the UR interface reports metres), where the published cooling
schedule accepts almost every proposal, and its proposal steps scale with the initial misfit; the rare
rejections can move one experiment's SA Large 5-point result, but not the distribution over experiments. So a
model's statistics are simulated once per DIRECTION of its weight vector and scaled analytically;
`tests/studies/test_reproduction.py` checks this against direct simulation (per experiment and in distribution).

Assumptions are data (`Layout.assumptions`), because the site layout, the registration corners, the origin of
N, the 5th point and the robot placement are only in the paper's Fig. 1.
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from rrbc_core import registration
from rrbc_core.errors import InputError
from rrbc_core.geometry import points as geometry
from rrbc_core.models.kinematics import UR5, UR5_TOOL_DOWN_SEED, forward, inverse_path, tool_down
from rrbc_core.registration.strategies import LinearMap, PiecewiseMap, clustering_sets, three_point_matrices
from rrbc_core.simulation import batch
from rrbc_core.studies.vanwyk2018_layouts import (  # noqa: F401 - the layouts are part of this module's API
    REPETITIONS,
    TOOL_MM,
    Layout,
    _by_name,
    layout_by_name,
    layouts,
)

#: Table II order.
METHODS = (
    "Small 3-point",
    "Large 3-point",
    "SA Small 3-point",
    "SA Large 3-point",
    "Clustering",
    "Large 5-point",
    "SA Large 5-point",
)
#: Registration data set each method uses; SA variants refine their base registration from the same readings.
METHOD_DATA = {
    "Small 3-point": "small3",
    "Large 3-point": "large3",
    "SA Small 3-point": "small3",
    "SA Large 3-point": "large3",
    "Clustering": "cluster",
    "Large 5-point": "large5",
    "SA Large 5-point": "large5",
}
SA_ITERATIONS = 5000  # not published; our default
SA_COST_UNIT_MM = 1000.0  # SA cost evaluated in m² (assumption, see module docstring)
#: Reference 1-sigma DH errors of one kinematic unit (docs/theory.md §5.1): joint zero offsets, link lengths, twists.
KINEMATIC_REFERENCE = {"joint_offset_deg": 0.1, "link_mm": 0.2, "twist_deg": 0.05}


# ------------------------------------------------------------------------------------------------------
# Perturbation components (unit size; robot frame, mm)
# ------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Component:
    name: str
    unit: str  # what weight 1 means, in words
    random: bool  # drawn per replicate (False: the same in every replicate)


COMPONENTS = {
    "noise": Component("noise", "sigma 1 mm per axis, independent per reading", True),
    "noise_xy": Component("noise_xy", "sigma 1 mm on x and y (horizontal), independent per reading", True),
    "noise_z": Component("noise_z", "sigma 1 mm on z (vertical), independent per reading", True),
    "noise_reach": Component(
        "noise_reach", "sigma per axis growing linearly with horizontal reach: 1 mm at the farthest point", True
    ),
    "kinematic": Component(
        "kinematic",
        "UR5 DH errors: 1 x (0.1 deg offsets, 0.2 mm lengths, 0.05 deg twists), one random robot per experiment",
        True,
    ),
    "scale": Component("scale", "robot/plate scale error of 1000 ppm about the robot base", False),
    "flatness": Component(
        "flatness", "smooth random plate-height field, RMS 1 mm over the sites, one per experiment", True
    ),
    "hole": Component(
        "hole", "per-hole seating offset, sigma 1 mm per axis, the same every time the hole is used", True
    ),
}
_STREAM = {name: i + 1 for i, name in enumerate(COMPONENTS)}


def _kinematic_sensitivity(points_robot: np.ndarray) -> np.ndarray:
    """(P, 3, 24) d(reported position)/d(DH error), DH errors in reference units (KINEMATIC_REFERENCE), at the
    nominal tool-down configuration of each point. First order: reported − physical = −G · p for a true robot
    nominal + p; the sign is immaterial (p is symmetric)."""
    dh = UR5.with_tool(TOOL_MM)
    rot = tool_down(0.0)
    q = inverse_path(dh, points_robot, rot, UR5_TOOL_DOWN_SEED)
    base, _ = forward(dh, q)
    g = np.empty((len(points_robot), 3, 24))
    names = ("theta_offset", "a", "d", "alpha")
    ref = (
        np.radians(KINEMATIC_REFERENCE["joint_offset_deg"]),
        KINEMATIC_REFERENCE["link_mm"],
        KINEMATIC_REFERENCE["link_mm"],
        np.radians(KINEMATIC_REFERENCE["twist_deg"]),
    )
    h = 1e-3
    for k, (name, unit) in enumerate(zip(names, ref)):
        for j in range(6):
            vals = {n: np.array(getattr(dh, n), dtype=float) for n in names}
            vals[name][j] += h * unit
            moved = type(dh)(vals["a"], vals["d"], vals["alpha"], vals["theta_offset"], dh.tool_mm)
            p, _ = forward(moved, q)
            g[:, :, 6 * k + j] = (p - base) / h
    return g


def _flatness_basis(points_n: np.ndarray) -> np.ndarray:
    """(P, 6) smooth height basis over the plate: products of Legendre polynomials up to total degree 3 that a
    rigid registration cannot absorb (degree >= 2), each normalised to unit RMS over the points."""
    xy = points_n[:, :2]
    lo, hi = xy.min(0), xy.max(0)
    u = 2 * (xy - lo) / np.where(hi > lo, hi - lo, 1.0) - 1
    x, y = u[:, 0], u[:, 1]
    p2 = lambda t: 0.5 * (3 * t * t - 1)
    p3 = lambda t: 0.5 * (5 * t**3 - 3 * t)
    cols = [p2(x), x * y, p2(y), p3(x), p2(x) * y, x * p2(y)]
    b = np.stack(cols, axis=1)
    return b / np.sqrt(np.mean(b**2, axis=0))


@dataclass(frozen=True)
class Geometry:
    """Everything per layout that does not depend on a model: truth, slots, component fields."""

    layout: Layout
    slot_point: np.ndarray  # (S,) point row of every reading slot
    reg_slots: dict  # data set -> (G, n) slot indices of its registration readings, G registrations
    check_slots: np.ndarray  # (7, 80) slot indices of each method's check readings
    check_reg: np.ndarray  # (80,) which of the G registrations each check sample uses
    check_point: np.ndarray  # (80,) site row of each check sample
    distance: np.ndarray  # (80,) distance of each check site from N's origin (mm)
    kin_g: np.ndarray  # (17, 3, 24)
    flat_basis: np.ndarray  # (17, 6)
    reach: np.ndarray  # (17,) horizontal distance from the base axis / its max over the sites
    scale_field: np.ndarray  # (17, 3) displacement of 1000 ppm about the base (mm)


def geometry_for(layout: Layout) -> Geometry:
    slots: list = []
    reg_slots = {}
    g = layout.registrations
    for name in ("small3", "large3", "large5", "cluster"):
        idx = layout.registration[name]
        reg_slots[name] = np.arange(len(slots), len(slots) + g * len(idx)).reshape(g, len(idx))
        slots += list(idx) * g
    check_point = np.repeat(np.arange(16), REPETITIONS)
    check_reg = np.tile(np.arange(REPETITIONS), 16) % g
    check_slots = np.empty((len(METHODS), len(check_point)), dtype=int)
    for m in range(len(METHODS)):
        check_slots[m] = np.arange(len(slots), len(slots) + len(check_point))
        slots += list(check_point)
    pr = layout.points_robot
    reach = np.linalg.norm(pr[:, :2], axis=1)
    return Geometry(
        layout=layout,
        slot_point=np.array(slots),
        reg_slots=reg_slots,
        check_slots=check_slots,
        check_reg=check_reg,
        check_point=check_point,
        distance=np.linalg.norm(layout.points_n[check_point], axis=1),
        kin_g=_kinematic_sensitivity(pr),
        flat_basis=_flatness_basis(layout.points_n),
        reach=reach / reach[:16].max(),
        scale_field=1e-3 * pr,
    )


@functools.lru_cache(maxsize=8)
def geometry_named(layout_name: str) -> Geometry:
    """`geometry_for` the named layout, built once per process (a worker reuses it for every task of a layout)."""
    return geometry_for(layout_by_name(layout_name))


def component_fields(geo: Geometry, name: str, replicates: int, seed: int) -> np.ndarray:
    """(R, S, 3) unit perturbation of component `name` at every reading slot (robot frame, mm)."""
    if name not in COMPONENTS:
        raise InputError(f"unknown perturbation component {name!r}; choose from {', '.join(COMPONENTS)}")
    s = geo.slot_point
    if name in ("noise", "noise_xy", "noise_z", "noise_reach"):
        rng = np.random.default_rng([seed, _STREAM["noise"]])  # one draw shared by the four noise forms
        n = rng.normal(size=(replicates, len(s), 3))
        if name == "noise_xy":
            n[..., 2] = 0.0
        elif name == "noise_z":
            n[..., :2] = 0.0
        elif name == "noise_reach":
            n *= geo.reach[s][None, :, None]
        return n
    rng = np.random.default_rng([seed, _STREAM[name]])
    if name == "kinematic":
        p = rng.normal(size=(replicates, geo.kin_g.shape[2]))
        return np.einsum("pij,rj->rpi", geo.kin_g, p)[:, s]
    if name == "scale":
        return np.broadcast_to(geo.scale_field[s][None], (replicates, len(s), 3)).copy()
    if name == "flatness":
        c = rng.normal(size=(replicates, geo.flat_basis.shape[1]))
        z = c @ geo.flat_basis.T
        z /= np.sqrt(np.mean(z[:, :16] ** 2, axis=1, keepdims=True))
        out = np.zeros((replicates, len(s), 3))
        out[..., 2] = z[:, s]
        return out
    # hole
    h = rng.normal(size=(replicates, len(geo.layout.points_n), 3))
    return h[:, s]


# ------------------------------------------------------------------------------------------------------
# Running the seven methods
# ------------------------------------------------------------------------------------------------------
def _clustering_inverse(sensor, readings, queries_robot, query_sites_n, check_reg, seed):
    """Per experiment and registration: the published clustering registration; each query is mapped back to N
    by its registration's kernel nearest its site. readings (R, G, n, 3), queries (R, 80, 3).

    The kernels and each cluster's points depend on the sensor points alone (`registration.clustering_sets`), so
    every registration's 3-point frames are computed in one batch per cluster and averaged as `clustering` does
    (the same operations, so the same numbers); a registration with a nearly collinear robot triple is made by
    `registration.clustering` itself."""
    r_count, g_count = readings.shape[:2]
    sensor = np.asarray(sensor, float)
    kernels, _, members = clustering_sets(sensor, 2, seed)
    ratio = geometry.SUBSET_DEGENERACY_RATIO
    pieces = []  # per cluster: (matrices (R, G, 3, 3), translations (R, G, 3)) of its rooted average
    regular = np.ones((r_count, g_count), bool)  # every subset of every cluster usable
    for j, chosen in enumerate(members):
        combos = np.array(list(itertools.combinations(range(len(chosen)), 3)))
        st = sensor[chosen][combos]  # (C, 3, 3)
        bt = readings[:, :, chosen][:, :, combos]  # (R, G, C, 3, 3)
        ok_s = geometry.collinear_ratio_batch(st) >= ratio
        ok_b = (geometry.collinear_ratio_batch(bt.reshape(-1, 3, 3)) >= ratio).reshape(bt.shape[:3])
        regular &= np.all(ok_b[:, :, ok_s], axis=2) if np.any(ok_s) else False
        st, bt = st[ok_s], bt[:, :, ok_s]
        c = len(st)
        mats = three_point_matrices(np.broadcast_to(st, bt.shape).reshape(-1, 3, 3), bt.reshape(-1, 3, 3)).reshape(
            r_count, g_count, c, 4, 4
        )
        m = mats.mean(axis=2)
        images = np.einsum("rgkij,j->rgki", mats[..., :3, :3], kernels[j]) + mats[..., :3, 3]
        pieces.append((m[..., :3, :3], images.mean(axis=2) - m[..., :3, :3] @ kernels[j]))
    out = np.empty(queries_robot.shape)
    for g in range(g_count):
        use = check_reg == g
        for k in range(r_count):
            if regular[k, g]:
                mapping = PiecewiseMap(kernels, tuple(LinearMap(a[k, g], t[k, g]) for a, t in pieces))
            else:
                reg = registration.clustering(sensor, readings[k, g], clusters=2, seed=seed)
                assert isinstance(reg.mapping, PiecewiseMap)
                mapping = reg.mapping
            out[k, use] = mapping.apply_inverse(queries_robot[k, use], mapping.piece_of(query_sites_n[use]))
    return out


def annealing_seeds(seed: int, count: int) -> np.ndarray:
    """(3, count) seeds of the three SA chains (small3, large3, large5) of each registration."""
    return np.random.default_rng([seed, 99]).integers(0, 2**31, size=(3, count))


def _back_to_n(a, t, q, check_reg):
    """x = A_g⁻¹ (q − t_g) per check sample, g its registration: a (R, G, 3, 3), t (R, G, 3), q (R, n, 3)."""
    ag, tg = a[:, check_reg], t[:, check_reg]
    return np.linalg.solve(ag, (q - tg)[..., None])[..., 0]


def method_errors(geo: Geometry, perturbation: np.ndarray, seed: int = 0, sa_seeds=None) -> np.ndarray:
    """Error vectors (R, 7, 80, 3) mm in frame N for readings truth + perturbation (R, S, 3).

    sa_seeds: (3, R·G) annealing seeds, G registrations per experiment (default `annealing_seeds(seed, R·G)`);
    a registration's chains depend only on its own seeds, so a batch of several directions can reuse one set
    per direction."""
    lay = geo.layout
    truth = lay.points_robot[geo.slot_point]
    readings = truth[None] + perturbation
    r_count = readings.shape[0]
    g_count = lay.registrations
    seeds = annealing_seeds(seed, r_count * g_count) if sa_seeds is None else np.asarray(sa_seeds)
    out = np.empty((r_count, len(METHODS), geo.check_slots.shape[1], 3))
    sites_n = lay.points_n[geo.check_point]

    def stacked(data):
        s = lay.points_n[lay.registration[data]]
        r = readings[:, geo.reg_slots[data]].reshape(r_count * g_count, len(s), 3)
        return np.broadcast_to(s, r.shape), r

    def shaped(a, t):
        return a.reshape(r_count, g_count, 3, 3), t.reshape(r_count, g_count, 3)

    def anneal(s, r, a, t, k):
        sa = batch.annealing_batch(
            s / SA_COST_UNIT_MM,
            r / SA_COST_UNIT_MM,
            seeds=seeds[k],
            iterations=SA_ITERATIONS,
            initial=(a, t / SA_COST_UNIT_MM),
        )
        return sa[0], sa[1] * SA_COST_UNIT_MM

    maps: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for k, data in enumerate(("small3", "large3")):
        s, r = stacked(data)
        a, t = batch.three_point_batch(s, r)
        maps[data] = shaped(a, t)
        maps["SA " + data] = shaped(*anneal(s, r, a, t, k))
    s5, r5 = stacked("large5")
    a5, t5 = batch.combinatorial_batch(s5, r5)
    maps["large5"] = shaped(a5, t5)
    maps["SA large5"] = shaped(*anneal(s5, r5, a5, t5, 2))
    key = {
        "Small 3-point": "small3",
        "Large 3-point": "large3",
        "SA Small 3-point": "SA small3",
        "SA Large 3-point": "SA large3",
        "Large 5-point": "large5",
        "SA Large 5-point": "SA large5",
    }
    for m, name in enumerate(METHODS):
        q = readings[:, geo.check_slots[m]]
        if name == "Clustering":
            sc = lay.points_n[lay.registration["cluster"]]
            back = _clustering_inverse(sc, readings[:, geo.reg_slots["cluster"]], q, sites_n, geo.check_reg, seed)
        else:
            back = _back_to_n(*maps[key[name]], q, geo.check_reg)
        out[:, m] = back - sites_n[None]
    return out


# ------------------------------------------------------------------------------------------------------
# Statistics of one simulated experiment
# ------------------------------------------------------------------------------------------------------
STATISTICS = ("mean_mm", "var_mm2", "max_mm", "r")
#: Power of the overall perturbation scale rho each statistic scales with.
SCALE_POWER = {"mean_mm": 1, "var_mm2": 2, "max_mm": 1, "r": 0}


def _pearson_rows(e: np.ndarray, d: np.ndarray) -> np.ndarray:
    ec = e - e.mean(axis=-1, keepdims=True)
    dc = d - d.mean()
    den = np.sqrt(np.sum(ec**2, axis=-1) * np.sum(dc**2))
    return np.where(den > 0, np.sum(ec * dc, axis=-1) / np.where(den > 0, den, 1.0), 0.0)


def ks_pvalues(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Two-sided two-sample KS p-values along the last axis, vectorised; the same asymptotic formula as
    `scipy.stats.ks_2samp(method="asymp")`: D = max |F_a − F_b|, p = kstwo.sf(D, round(n m / (n + m)))."""
    n, m = a.shape[-1], b.shape[-1]
    both = np.concatenate([a, b], axis=-1)
    order = np.argsort(both, axis=-1, kind="stable")
    step = np.where(order < n, 1.0 / n, -1.0 / m)
    srt = np.take_along_axis(both, order, axis=-1)
    cdf_diff = np.cumsum(step, axis=-1)
    # only compare after the last of a run of ties
    last = np.concatenate([srt[..., 1:] != srt[..., :-1], np.ones(srt.shape[:-1] + (1,), dtype=bool)], axis=-1)
    d = np.max(np.where(last, np.abs(cdf_diff), 0.0), axis=-1)
    # D takes few distinct values (multiples of 1/n and 1/m, to rounding): the exact tail once per value
    values, where = np.unique(d, return_inverse=True)
    return stats.kstwo.sf(values, np.round(n * m / (n + m)))[where].reshape(d.shape)


def statistics(errors: np.ndarray, distance: np.ndarray) -> dict:
    """Per-experiment statistics of error vectors (R, 7, n, 3): {name: (R, 7)}; 'ks_p' (R, 7) against the
    previous method (column 0 NaN); 'norms' (R, 7, n) and 'horizontal' (R, 7, n) for the peg model."""
    e = np.linalg.norm(errors, axis=-1)
    out = {
        "mean_mm": e.mean(axis=-1),
        "var_mm2": e.var(axis=-1, ddof=1),
        "max_mm": e.max(axis=-1),
        "r": _pearson_rows(e, distance),
        "norms": e,
        "horizontal": np.linalg.norm(errors[..., :2], axis=-1),
    }
    ks = np.full(e.shape[:2], np.nan)
    ks[:, 1:] = ks_pvalues(e[:, 1:], e[:, :-1])
    out["ks_p"] = ks
    return out


# ------------------------------------------------------------------------------------------------------
# Models and their direction grids
# ------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Model:
    """A candidate error model: a noise component and at most one extension, weights (rho cos phi, rho sin phi).

    params(rho, phi) gives the physical parameters: each component's weight times `scale` in `units`.
    """

    name: str
    components: tuple  # 1 or 2 component names
    labels: tuple  # parameter label per component
    scales: tuple  # physical value of weight 1 per component
    cause: str  # what the extension stands for, in words
    phis: tuple = field(default=())  # grid of directions (rad); () = baseline (phi = 0 only)

    def params(self, rho: float, phi: float) -> dict:
        w = (rho,) if len(self.components) == 1 else (rho * np.cos(phi), rho * np.sin(phi))
        return {lab: float(wi * sc) for lab, wi, sc in zip(self.labels, w, self.scales)}

    def weights(self, phi: float) -> np.ndarray:
        return np.array([1.0]) if len(self.components) == 1 else np.array([np.cos(phi), np.sin(phi)])


#: Directions: extension-to-first-component weight ratios from 0 to infinity, denser where both matter (the
#: statistics are interpolated between them with a cubic spline in phi, `model_fit.Moments`).
_RATIOS = (0.0, 0.1, 0.25, 0.4, 0.6, 0.8, 1.0, 1.3, 1.8, 2.5, 4.0, 7.0)
_PHIS = tuple(float(np.arctan(r)) for r in _RATIOS) + (float(np.pi / 2),)

MODELS = (
    Model("baseline", ("noise",), ("sigma_mm",), (1.0,), "rigid truth + isotropic Gaussian robot noise"),
    Model(
        "kinematic",
        ("noise", "kinematic"),
        ("sigma_mm", "dh_scale"),
        (1.0, 1.0),
        "a UR5 kinematic (DH parameter) error field",
        _PHIS,
    ),
    Model(
        "scale",
        ("noise", "scale"),
        ("sigma_mm", "scale_ppm"),
        (1.0, 1000.0),
        "a uniform scale mismatch between robot and plate",
        _PHIS,
    ),
    Model(
        "flatness",
        ("noise", "flatness"),
        ("sigma_mm", "flatness_rms_mm"),
        (1.0, 1.0),
        "a smooth plate-height (flatness) error",
        _PHIS,
    ),
    Model(
        "anisotropic",
        ("noise_xy", "noise_z"),
        ("sigma_xy_mm", "sigma_z_mm"),
        (1.0, 1.0),
        "anisotropic noise (horizontal vs vertical seating scatter)",
        _PHIS,
    ),
    Model(
        "site_noise",
        ("noise", "noise_reach"),
        ("sigma_mm", "sigma_reach_mm"),
        (1.0, 1.0),
        "site-dependent noise growing with the robot's reach",
        _PHIS,
    ),
    Model(
        "seating",
        ("noise", "hole"),
        ("sigma_mm", "hole_offset_mm"),
        (1.0, 1.0),
        "a repeatable per-hole collimator seating offset",
        _PHIS,
    ),
)


def model_by_name(name: str) -> Model:
    return _by_name(MODELS, name, "model")


@dataclass(frozen=True)
class DirectionStats:
    """A model's simulated statistics at unit scale rho = 1, per direction phi: arrays (len(phis), R, 7)."""

    model: Model
    phis: np.ndarray
    values: dict  # statistic -> (Φ, R, 7); also 'ks_p'
    horizontal: np.ndarray  # (Φ, R, 7, 80) horizontal error norms (peg model)
    norms: np.ndarray  # (Φ, R, 7, 80)
    replicates: int


def simulate_model(geo: Geometry, model: Model, replicates: int, seed: int, progress=None, phis=None) -> DirectionStats:
    """Simulate `replicates` experiments per direction of `model` (unit scale), common random numbers."""
    phis = np.array(model.phis if phis is None else phis, dtype=float)
    if phis.size == 0:
        phis = np.zeros(1)
    fields = [component_fields(geo, c, replicates, seed) for c in model.components]
    # all directions in one batch (the SA's per-iteration cost is shared by every chain in the batch)
    pert = np.concatenate([sum(wi * f for wi, f in zip(model.weights(phi), fields)) for phi in phis])
    seeds = np.tile(
        annealing_seeds(seed, replicates * geo.layout.registrations), (1, len(phis))
    )  # same chains per direction
    st = statistics(method_errors(geo, pert, seed, seeds), geo.distance)
    shape = (len(phis), replicates)
    vals = {k: st[k].reshape(shape + st[k].shape[1:]) for k in (*STATISTICS, "ks_p")}
    hor = st["horizontal"].reshape(shape + st["horizontal"].shape[1:])
    nor = st["norms"].reshape(shape + st["norms"].shape[1:])
    if progress is not None:
        progress.update(len(phis))
    return DirectionStats(model, phis, vals, hor, nor, replicates)


# ------------------------------------------------------------------------------------------------------
# Peg success (Table III) from an error distribution
# ------------------------------------------------------------------------------------------------------
def success_probability(horizontal: np.ndarray, capture_mm) -> np.ndarray:
    """Per method, the simulated probability that one insertion succeeds: horizontal error < capture radius.

    horizontal: (R, 7, n) horizontal error norms (mm); capture_mm: scalar or (C,) -> (C, 7)."""
    c = np.atleast_1d(np.asarray(capture_mm, dtype=float))
    return np.mean(horizontal[None] < c[:, None, None, None], axis=(1, 3))


# ------------------------------------------------------------------------------------------------------
# RRBC on the breadboard: leave-one-site-out
# ------------------------------------------------------------------------------------------------------
def rrbc_gain(
    geo: Geometry,
    model: Model,
    rho: float,
    phi: float,
    replicates: int,
    seed: int,
    neighbours: int = 4,
    power: float = 2.0,
) -> dict:
    """What `model` at (rho, phi) predicts RRBC does on the plate (RMS errors in mm over sites and experiments).

    Registration: Large 5-point (element-wise average, as published). Fiducials: the 16 sites, one reading
    each; each site is then a target in turn, corrected by IDW (K nearest of the other 15 fiducials, 1/d^p) and
    reached with a fresh reading (new noise, same bias). Rigid error = that reading's registration error;
    RRBC error = rigid error minus the interpolated correction (frame N, first order)."""
    fields = [component_fields(geo, c, replicates, seed) for c in model.components]
    pert = rho * sum(w * f for w, f in zip(model.weights(phi), fields))
    lay = geo.layout
    truth = lay.points_robot[geo.slot_point]
    readings = truth[None] + pert
    s5 = lay.points_n[lay.registration["large5"]]
    r5 = readings[:, geo.reg_slots["large5"][0]]  # the first registration
    a5, t5 = batch.combinatorial_batch(np.broadcast_to(s5, r5.shape), r5)
    m5 = METHODS.index("Large 5-point")
    slots = geo.check_slots[m5].reshape(16, REPETITIONS)
    sites = lay.points_n[:16]
    fid = batch.apply_inverse_batch(a5, t5, readings[:, slots[:, 0]], rigid=False) - sites[None]
    tgt = batch.apply_inverse_batch(a5, t5, readings[:, slots[:, 1]], rigid=False) - sites[None]
    corr = np.empty_like(tgt)
    for k in range(16):
        others = np.delete(np.arange(16), k)
        corr[:, k] = batch.idw_batch(
            np.broadcast_to(sites[others], (replicates, 15, 3)), fid[:, others], sites[k][None], neighbours, power
        )[:, 0]
    rigid = np.sqrt(np.mean(np.sum(tgt**2, axis=-1)))
    after = np.sqrt(np.mean(np.sum((tgt - corr) ** 2, axis=-1)))
    noise_only = [c for c in model.components if c.startswith("noise")]
    return {
        "rmst_rigid_mm": float(rigid),
        "rmst_rrbc_mm": float(after),
        "change": float(after / rigid - 1.0),
        "noise_components": noise_only,
    }
