"""Model-based calibration (volumetric error compensation, VEC) of a serial arm together with the sensor-to-robot
transform, from measured poses with joint values (docs/calibration.md).

Model. A row measured with joint values q has its physical point at FK(δ, q), the forward kinematics of the arm's
chain (`models.chain.Chain`: from a URDF or a DH table) with the TRUE parameter errors δ (joint zero offsets, errors
of the joints' origins, the tool point); the sensor reads it at s = T⁻¹(FK(δ, q)) + noise. Identification minimises
Σ |T(s_i) − FK(δ, q_i)|² (robot frame, mm) over δ and T (robot = R @ sensor + t), by Gauss–Newton with the chain's
exact analytic Jacobians (every pose at once); a step that does not lower the sum is damped (Levenberg: an error the
model does not hold, a bending arm fitted with geometric terms alone, can make full steps overshoot), so the
iteration ends at the least-squares fit and not short of it. With load terms
(`models.loads`: joint compliance under gravity, a column's bending, backlash) FK includes their deflections and
their coefficients are fitted beside δ.

Identifiability. Not every parameter can be told apart from these data: an error of the base is absorbed by T,
some errors act alike at the data's poses. At each step (parameters scaled to mm: angles × `angle_scale`, half the
chain's reach), the singular value decomposition of the residuals' Jacobian gives the combinations the data
determine (singular value above `RANK_TOL` of the largest); the fit moves only along those, the others stay at
their nominal values. Uncertainty: σ̂² (JᵀJ)⁺ in the identified subspace, σ̂² = RSS / (3N − r). A parameter is
identifiable on its own when its unit change lies in that subspace; the others are reported in combinations.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.geometry.transforms import map_points, skew
from rrbc_core.models.chain import Chain, rotation
from rrbc_core.models.loads import GRAVITY, Loads, LoadTerm, deflections, factor_scale, gravity_loads, term_jacobian

RANK_TOL = 1e-4  # singular values below this fraction of the largest: a combination the data do not determine
MAX_STEPS = 30  # Gauss–Newton steps at most (it converges in a few on data the model describes)
MAX_HALVINGS = 12  # a step is damped more at most this often before the iteration stops (no lower residuals found)
STEP_TOL_MM = 1e-9  # a step that moves no scaled parameter by more than this (mm) ends the iteration
COST_TOL = 1e-10  # a step that lowers the sum of squares by less than this fraction of it ends the iteration
# Levenberg's damping λ (a fraction of the largest singular value squared): none while full Gauss–Newton steps lower
# the residuals; from DAMPING_START, times DAMPING_UP per rejected step, times DAMPING_DOWN per accepted one, and
# none again below DAMPING_MIN
DAMPING_START, DAMPING_UP, DAMPING_DOWN, DAMPING_MIN = 1e-6, 10.0, 0.3, 1e-9
MIN_POSES = 6
#: the warning of an arm fit that stopped after MAX_STEPS steps still lowering its residuals (`Calibration.converged`)
NOT_CONVERGED = (
    f"the arm fit stopped after {MAX_STEPS} steps while its residuals were still falling: VEC's figures may be short "
    "of the model's least-squares fit (an arm model far from the data, or data that barely determine it)"
)
TERM_ALONE_TOL = 1e-2


def angle_scale(chain: Chain) -> float:
    """mm per rad used to compare angles with lengths: half the chain's reach (an angle error of 1 rad moves a point
    about that far)."""
    return 0.5 * chain.reach_mm()


def _exp(w: np.ndarray) -> np.ndarray:
    a = float(np.linalg.norm(w))
    return np.eye(3) if a == 0.0 else rotation(w / a, np.array(a))


@dataclass(frozen=True, eq=False)
class Calibration:
    """An identified arm and registration.

    `chain` the nominal model; `delta` (P,) identified errors in `chain.param_names` order (rad for angles, mm
    otherwise) with `delta_se` (P,) standard errors (NaN where a parameter is not identifiable on its own) and
    `identifiable` (P,) bool; `rotation` (3, 3), `translation` (3,) mm: sensor → robot; `rank` the number of
    identified combinations, `combinations` their descriptions (the largest loadings), `sigma_mm` the residual noise
    per axis, `residuals` (N, 3) mm; `chi2`, `chi2_dof`: the identified arm errors against their uncertainty."""

    chain: Chain
    delta: np.ndarray
    delta_se: np.ndarray
    identifiable: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    rank: int
    combinations: tuple
    sigma_mm: float
    residuals: np.ndarray
    chi2: float = float("nan")
    chi2_dof: int = 0
    #: stations (`groups` given to `calibrate`): one transform each, (G, 3, 3) and (G, 3); `rotation`/`translation`
    #: are the first station's. None for one transform.
    rotations: np.ndarray | None = None
    translations: np.ndarray | None = None
    #: load terms (`models.loads`): the terms, their coefficients (T,) (rad/Nm or rad) with standard errors (NaN
    #: where not identifiable on its own) and identifiability, and the gravity vector (3,) m/s², base frame
    terms: tuple[LoadTerm, ...] = ()
    coef: np.ndarray = field(default_factory=lambda: np.zeros(0))
    coef_se: np.ndarray = field(default_factory=lambda: np.zeros(0))
    coef_identifiable: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    gravity: tuple = GRAVITY
    #: the covariance of every identified parameter (P + T + 6G: the chain's, the load terms', each transform's
    #: rotation vector and translation) in their own units (rad, mm, rad/Nm), on the identified combinations only
    param_cov: np.ndarray | None = None
    #: False when the iteration stopped after `MAX_STEPS` steps still lowering the residuals (short of the fit)
    converged: bool = True

    @property
    def names(self) -> tuple[str, ...]:
        return self.chain.param_names

    def deflections(self, q) -> tuple[np.ndarray | None, np.ndarray | None]:
        """The identified load terms' joint deflections (dv, drot) at inputs q (N, I) (`models.loads.deflections`),
        (None, None) without terms."""
        if not self.terms:
            return None, None
        return deflections(self.chain, self.terms, self.coef, gravity_loads(self.chain, q, self.gravity))

    @property
    def kinematic_p_value(self) -> float:
        """P-value of "no kinematic error" (χ² of the identified arm errors against their uncertainty)."""
        from scipy.stats import chi2

        return float(chi2.sf(self.chi2, self.chi2_dof)) if self.chi2_dof else 1.0

    def sensor_to_robot(self, s, groups=None) -> np.ndarray:
        """T(s) (N, 3) robot frame, mm; with stations, `groups` (N,) says whose transform each row takes."""
        s = np.asarray(s, float).reshape(-1, 3)
        if self.rotations is None or self.translations is None or groups is None:
            return map_points(s, self.rotation, self.translation)
        g = np.asarray(groups, int)
        return np.einsum("nij,nj->ni", self.rotations[g], s) + self.translations[g]

    def prediction_cov(self, q, s, groups=None) -> np.ndarray:
        """(D, 3, 3) mm², robot frame: what the identified parameters' uncertainty (`param_cov`) leaves in
        T(s) − FK(q) at rows with joint values q (D, I) and sensor readings s (D, 3) (with stations, `groups` (D,)):
        the arm model's part of a VEC command's error there. Zeros without `param_cov`."""
        qa = np.asarray(q, float)
        sa = np.asarray(s, float).reshape(-1, 3)
        if self.param_cov is None or not len(sa):
            return np.zeros((len(sa), 3, 3))
        rot = self.rotations if self.rotations is not None else self.rotation[None]
        t = self.translations if self.translations is not None else self.translation[None]
        g = np.zeros(len(sa), int) if groups is None or self.rotations is None else np.asarray(groups, int)
        loads = gravity_loads(self.chain, qa, self.gravity) if self.terms else None
        _, j = _system(self.chain, qa, sa, self.delta, rot, t, g, self.terms, self.coef, loads)
        jj = j.reshape(len(sa), 3, -1)
        return np.einsum("nik,kl,njl->nij", jj, self.param_cov, jj)

    def forward(self, q) -> np.ndarray:
        """Where the identified arm's tool point is at inputs q (N, I), robot frame, mm (its load terms included)."""
        dv, drot = self.deflections(q)
        return self.chain.kinematics(q, self.delta, jacobians=False, dv=dv, drot=drot)[0]


def _scales(chain: Chain, n_groups: int = 1, term_scales=()) -> np.ndarray:
    """Per parameter (P + T + 6G: the chain's, the load terms', then each transform's rotation vector and
    translation), mm per unit."""
    a = angle_scale(chain)
    n_t = len(term_scales)
    sc = np.ones(chain.n_params + n_t + 6 * n_groups)
    sc[: chain.n_params][chain.angular] = a
    sc[chain.n_params : chain.n_params + n_t] = a * np.asarray(term_scales, float)
    for g in range(n_groups):
        k = chain.n_params + n_t + 6 * g
        sc[k : k + 3] = a
    return sc


def _system(
    chain: Chain, q, s, delta, rot, t, groups, terms=(), coef=None, loads=None
) -> tuple[np.ndarray, np.ndarray]:
    """Residuals (3N,) = T_g(s) − FK(δ, q, deflections) and their Jacobian (3N, P + T + 6G) in the parameters' own
    units; rot (G, 3, 3), t (G, 3), groups (N,) each row's transform; `terms` with coefficients `coef` (T,) and the
    poses' `loads` (`models.loads`)."""
    dv = drot = None
    if terms:
        assert loads is not None and coef is not None
        dv, drot = deflections(chain, terms, coef, loads)
    p, jp, _ = chain.kinematics(q, delta, dv=dv, drot=drot)
    assert jp is not None
    rs = np.einsum("nij,nj->ni", rot[groups], s)
    res = rs + t[groups] - p
    n, n_p, n_t, n_g = len(q), chain.n_params, len(terms), len(rot)
    j = np.zeros((n, 3, n_p + n_t + 6 * n_g))
    j[:, :, :n_p] = -jp
    if terms:
        assert loads is not None
        j[:, :, n_p : n_p + n_t] = -term_jacobian(terms, loads, jp)
    rows = np.arange(n)
    k0 = n_p + n_t
    for a in range(3):
        j[rows, :, k0 + 6 * groups + a] = -skew(rs)[:, :, a]
        j[rows, :, k0 + 6 * groups + 3 + a] = np.eye(3)[:, a]
    return res.reshape(-1), j.reshape(3 * n, -1)


def _describe(names: tuple, v: np.ndarray, k: int = 3) -> str:
    top = np.argsort(-np.abs(v))[:k]
    return " ".join(f"{'+' if v[i] >= 0 else '-'}{abs(v[i]):.2f}·{names[i]}" for i in top)


def calibrate(
    chain: Chain, q, sensor, rotation0=None, translation0=None, groups=None, terms=(), gravity=None
) -> Calibration:
    """Identify the arm's errors and the sensor-to-robot transform from N poses (module docstring).

    Parameters
    ----------
    chain : Chain
        The arm's nominal model, its tool point included.
    q : array_like, (N, I)
        Joint values per pose, rad or mm (`io.joints.joint_values`).
    sensor : array_like, (N, 3)
        The sensor's readings of the tool point, sensor frame, mm.
    rotation0, translation0 : array_like, optional
        A starting registration, (3, 3) and (3,), or with `groups` (G, 3, 3) and (G, 3) (default: the least-squares
        fit of each station's readings to the nominal arm).
    groups : array_like of int, (N,), optional
        Stations 0..G-1: one sensor-to-robot transform each, the arm's errors shared by all.
    terms : sequence of LoadTerm, optional
        Load terms identified beside the geometric errors (`models.loads.candidate_terms`), under `gravity` (3,)
        m/s² in the base frame (default: the base frame's −z).

    Raises
    ------
    InputError
        Fewer than `MIN_POSES` poses, or mismatched shapes.
    """
    qa = np.asarray(q, float)
    s = np.asarray(sensor, float).reshape(-1, 3)
    if qa.ndim != 2 or len(qa) != len(s):
        raise InputError(f"{len(qa)} joint configurations for {len(s)} sensor readings")
    if len(qa) < MIN_POSES:
        raise InputError(f"calibration needs at least {MIN_POSES} poses with joint values, got {len(qa)}")
    grouped = groups is not None
    gi = np.zeros(len(qa), int) if groups is None else np.asarray(groups, int).reshape(-1)
    if len(gi) != len(qa) or (len(gi) and gi.min() < 0):
        raise InputError(f"{len(gi)} station labels for {len(qa)} poses")
    n_g = int(gi.max()) + 1 if len(gi) else 1
    p_nominal = chain.forward(qa)
    if rotation0 is None:
        from rrbc_core.registration import register

        maps = [register("least-squares", s[gi == g], p_nominal[gi == g]).mapping for g in range(n_g)]
        rotation0 = np.array([m.rotation for m in maps])
        translation0 = np.array([m.translation for m in maps])
    rot = np.asarray(rotation0, float).reshape(-1, 3, 3).copy()
    t = np.asarray(translation0, float).reshape(-1, 3).copy()
    n_p, n_t = chain.n_params, len(terms)
    terms = tuple(terms)
    loads: Loads | None = gravity_loads(chain, qa, gravity) if terms else None
    delta, coef = np.zeros(n_p), np.zeros(n_t)
    sc = _scales(chain, n_g, [factor_scale(tm, loads) for tm in terms] if loads is not None else ())
    k0 = n_p + n_t
    res, j = _system(chain, qa, s, delta, rot, t, gi, terms, coef, loads)
    cost = float(res @ res)
    damping = 0.0  # Levenberg's λ, relative to the largest singular value squared; 0: a Gauss–Newton step
    converged = False  # stopped by a tolerance, or where no damped step lowers the residuals: not by MAX_STEPS
    for _ in range(MAX_STEPS):
        js = j / sc
        u, sv, vt = np.linalg.svd(js, full_matrices=False)
        rank = int(np.sum(sv > RANK_TOL * sv[0]))
        basis = vt[:rank].T
        grad = u[:, :rank].T @ res
        for _ in range(MAX_HALVINGS):  # a step that does not lower the residuals is damped more (Levenberg)
            z = -sv[:rank] * grad / (sv[:rank] ** 2 + damping * sv[0] ** 2)
            step_scaled = basis @ z
            step = step_scaled / sc
            d_new, c_new = delta + step[:n_p], coef + step[n_p:k0]
            r_new, t_new = rot.copy(), t.copy()
            for g in range(n_g):
                k = k0 + 6 * g
                r_new[g] = _exp(step[k : k + 3]) @ rot[g]
                t_new[g] = t[g] + step[k + 3 : k + 6]
            res_new, j_new = _system(chain, qa, s, d_new, r_new, t_new, gi, terms, c_new, loads)
            if float(res_new @ res_new) <= cost:
                damping = 0.0 if damping < DAMPING_MIN else damping * DAMPING_DOWN
                break
            damping = DAMPING_START if damping < DAMPING_MIN else damping * DAMPING_UP
        else:
            converged = True  # not even a short step along the gradient lowers them: a minimum
            break
        gain = cost - float(res_new @ res_new)
        delta, coef, rot, t, res, j = d_new, c_new, r_new, t_new, res_new, j_new
        cost = float(res @ res)
        if np.max(np.abs(step_scaled)) < STEP_TOL_MM or gain <= COST_TOL * cost:
            converged = True
            break
    js = j / sc
    _, sv, vt = np.linalg.svd(js, full_matrices=False)
    rank = int(np.sum(sv > RANK_TOL * sv[0]))
    basis = vt[:rank].T
    dof = max(3 * len(qa) - rank, 1)
    sigma2 = float(np.sum(res**2) / dof)
    jr = js @ basis
    cov_z = sigma2 * np.linalg.pinv(jr.T @ jr)
    cov = (basis @ cov_z @ basis.T) / np.outer(sc, sc)
    se = np.sqrt(np.clip(np.diag(cov), 0, None))
    # is there a kinematic error at all? H0: the arm's identified combinations are zero (δ = 0 up to what the
    # transform absorbs). χ² = δᵀ Cov(δ)⁺ δ with its rank as the degrees of freedom, δ in the scaled units.
    cov_arm = (basis @ cov_z @ basis.T)[:n_p, :n_p]
    d_scaled = delta * sc[:n_p]
    w, v = np.linalg.eigh(cov_arm)
    keep = w > w.max() * 1e-9 if w.max() > 0 else np.zeros(len(w), bool)
    chi2 = float(np.sum((v[:, keep].T @ d_scaled) ** 2 / w[keep])) if keep.any() else 0.0
    null = np.eye(k0 + 6 * n_g) - basis @ basis.T
    alone = np.linalg.norm(null, axis=0) < 1e-3  # a unit change of this parameter lies in the identified space
    # a load term counts as identified when at most 1 % of its unit change lies outside that space (a column's
    # bending shares most of its effect with the shoulder's compliance, never all of it)
    alone[n_p:k0] = np.linalg.norm(null, axis=0)[n_p:k0] < TERM_ALONE_TOL
    tnames = ("rx", "ry", "rz", "x", "y", "z")
    names = (
        chain.param_names
        + tuple(tm.name for tm in terms)
        + tuple(f"T.{c}" if not grouped else f"T[{g}].{c}" for g in range(n_g) for c in tnames)
    )
    return Calibration(
        chain=chain,
        delta=delta,
        delta_se=np.where(alone[:n_p], se[:n_p], np.nan),
        identifiable=alone[:n_p],
        rotation=rot[0],
        translation=t[0],
        rank=rank,
        combinations=tuple(_describe(names, basis[:, k]) for k in range(rank)),
        sigma_mm=float(np.sqrt(sigma2)),
        residuals=res.reshape(-1, 3),
        chi2=chi2,
        chi2_dof=int(keep.sum()),
        rotations=rot if grouped else None,
        translations=t if grouped else None,
        terms=terms,
        coef=coef,
        coef_se=np.where(alone[n_p:k0], se[n_p:k0], np.nan),
        coef_identifiable=alone[n_p:k0],
        gravity=tuple(float(v) for v in (GRAVITY if gravity is None else gravity)),
        param_cov=cov,
        converged=converged,
    )


def fixed_transforms(cal: Calibration, q, sensor, groups, n_groups: int, grouped: bool) -> Calibration:
    """`cal`'s arm kept as it is, with each station's sensor-to-robot transform fitted anew (least squares) to N rows:
    sensor readings (N, 3) mm of the tool point at inputs q (N, I), `groups` (N,) their stations 0..n_groups-1 (each
    with 3 rows or more). `grouped`: one transform per station (else the first is the only one)."""
    from rrbc_core.registration import register

    p = cal.forward(q)
    s = np.asarray(sensor, float).reshape(-1, 3)
    g = np.asarray(groups, int)
    maps = [register("least-squares", s[g == k], p[g == k]).mapping for k in range(n_groups)]
    rot = np.array([m.rotation for m in maps], float)
    t = np.array([m.translation for m in maps], float)
    res = np.einsum("nij,nj->ni", rot[g], s) + t[g] - p
    return replace(
        cal,
        rotation=rot[0],
        translation=t[0],
        rotations=rot if grouped else None,
        translations=t if grouped else None,
        residuals=res,
        sigma_mm=float(np.sqrt(np.sum(res**2) / max(res.size - 6 * n_groups, 1))),
    )


def position_jacobian(chain: Chain, q) -> np.ndarray:
    """∂FK/∂δ (N, 3, P) of the nominal chain at inputs q (N, I): how the tool point (robot frame, mm) moves per unit
    of each parameter in `chain.param_names`, angles scaled by `angle_scale` (every column in mm per mm-equivalent)."""
    _, jp, _ = chain.kinematics(q)
    assert jp is not None
    return jp / _scales(chain)[: chain.n_params]


def vec_commands(cal: Calibration, s_rows, q_rows, groups=None) -> np.ndarray:
    """VEC's robot commands (D, 3) for rows with sensor readings s_rows (D, 3) and joint values q_rows (D, I)
    (with stations, `groups` (D,): each row's station).

    The point p = T(s); the joints q* that put the IDENTIFIED arm's tool point there (two damped least-squares steps
    of position-only inverse kinematics from the row's joints, every row at once); the command the NOMINAL
    controller needs to reach q*: b̂ = p + FK(0, q*) − FK(δ̂, q*) — exact to first order in δ̂ times the step, which
    is far below the noise where the row's joints are the ones that reach the point."""
    chain = cal.chain
    q = np.asarray(q_rows, float).copy()
    p = cal.sensor_to_robot(s_rows, groups)
    if len(q) == 0:
        return np.zeros((0, 3))
    a = angle_scale(chain)
    w = np.array([1.0 if i.kind == "prismatic" else a for i in chain.inputs])  # joint units -> mm-equivalent
    for _ in range(2):
        dv, drot = cal.deflections(q)
        pid, _, jq = chain.kinematics(q, cal.delta, dv=dv, drot=drot)
        assert jq is not None
        js = jq / w  # mm per mm-equivalent
        m = js @ np.swapaxes(js, 1, 2) + (1e-9 * a * a) * np.eye(3)
        step = np.einsum("nji,nj->ni", js, np.linalg.solve(m, (p - pid)[..., None])[..., 0])
        q = q + step / w
    return p + chain.forward(q) - cal.forward(q)
