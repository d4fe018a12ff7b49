"""Registration error metrics and first-order error prediction.

Frames and units
----------------
All points are rows (N x 3 or M x 3) in millimetres. Prediction functions work in ONE frame, the frame the
registration maps INTO (the destination / robot frame B of docs/theory.md §0): the fiducials, the targets, the
FLE covariances and the bias fields must all be expressed in that frame. Error-prediction formulas are
invariant to a rigid motion of that frame, so any frame rigidly attached to B gives the same numbers, provided
every input (including covariance matrices, rotated as Q Σ Qᵀ) is expressed in it.

Net FLE (docs/theory.md §0): with sensor noise ε_i (covariance Σ_s,i, sensor frame) and robot noise η_i
(covariance Σ_b,i, robot frame), the fit sees δ_i = R ε_i − η_i in the robot frame, with covariance

    Σ_i = R Σ_s,i Rᵀ + Σ_b,i,           isotropic case: <FLE²> = E‖δ_i‖² = 3σ_s² + 3σ_b².

Sign convention: TRE(r) = (registered position of target r) − (true position of r), in the destination frame.

Formulas
--------
* Fitzpatrick, West & Maurer, IEEE TMI 17(5):694–702 (1998), eq. 46 (docs/theory.md §2.1):
  <TRE²(r)> ≈ <FLE²>/N · (1 + (1/3) Σ_k d_k²/f_k²).
* <FRE²> ≈ (1 − 2/N) <FLE²> (same paper; docs/theory.md §2.2).
* Danilchenko & Fitzpatrick, IEEE TMI 30(3):679–693 (2011), general first-order TRE covariance with
  anisotropic, inhomogeneous FLE and arbitrary weights (docs/theory.md §2.3), with A(x) = [−[x]_× | I₃]:
  H = Σ A_iᵀ M_i A_i,  B = Σ A_iᵀ M_i Σ_i M_i A_i,  Cov(p) = H⁻¹ B H⁻¹,  Cov(TRE(r)) = A(r) Cov(p) A(r)ᵀ.
* Deterministic bias floor (docs/theory.md §2.3): TRE_bias(r) = β(r) − A(r) H⁻¹ Σ A_iᵀ M_i β(x_i).

Both first-order forms are computed about the fiducial centroid with coordinates divided by the fiducials'
RMS radius. This reparametrises p = (δθ, δt) linearly and leaves every result unchanged; it only keeps H
well conditioned when coordinates are hundreds of mm away from the origin.

Degenerate fiducial sets (fewer than 3 points, coincident or collinear points, or weights that leave a
degree of freedom unconstrained) make H singular: those raise `InputError`, never return NaN/inf.
"""

from __future__ import annotations

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.geometry.points import as_points

# H (6x6, after centring and scaling) is treated as singular when its smallest eigenvalue is below this
# fraction of its largest. For uniform weights the rotational eigenvalues are N f_k² / s², so this is the
# same as f_min/f_max < 1e-6: e.g. points spread 1 m along a line but only 1 µm off it. Such a set is
# collinear for every practical purpose (the rotation about the line is undetermined).
_SINGULAR_RATIO = 1e-12


# --------------------------------------------------------------------------------------------------------
# validation helpers
# --------------------------------------------------------------------------------------------------------
def _finite_array(x, what: str) -> np.ndarray:
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{what} must be numeric: {exc}") from None
    if not np.all(np.isfinite(a)):
        raise InputError(f"{what} contain a non-finite value (NaN or infinity)")
    return a


def _points(x, what: str, allow_empty: bool = False) -> np.ndarray:
    return as_points(x, what, empty=allow_empty)


def _fiducials(x) -> np.ndarray:
    f = _points(x, "fiducials")
    if len(f) < 3:
        raise InputError(f"fiducials: {len(f)} given, a rigid registration needs at least 3 non-collinear points")
    return f


def _scalar(x, what: str, minimum: float = 0.0) -> float:
    a = _finite_array(x, what)
    if a.ndim != 0:
        raise InputError(f"{what} must be a single number, got shape {a.shape}")
    v = float(a)
    if v < minimum:
        raise InputError(f"{what} must be >= {minimum}, got {v}")
    return v


def _check_spd_stack(c: np.ndarray, what: str) -> np.ndarray:
    """Check that every 3x3 matrix of a stack (..., 3, 3) is symmetric positive semi-definite; symmetrise."""
    scale = np.max(np.abs(c)) if c.size else 0.0
    if np.max(np.abs(c - np.swapaxes(c, -1, -2)), initial=0.0) > 1e-6 * scale:
        raise InputError(f"{what} must be symmetric (a covariance or weight matrix is symmetric)")
    c = 0.5 * (c + np.swapaxes(c, -1, -2))
    if c.size and np.min(np.linalg.eigvalsh(c)) < -1e-9 * scale:
        raise InputError(f"{what} must be positive semi-definite (a negative variance is not possible)")
    return c


def _cov_stack(x, n: int, what: str, count_name: str) -> np.ndarray:
    """A (3,3) matrix shared by all n items, or one (n,3,3) per item; returns (n,3,3)."""
    c = _finite_array(x, what)
    if c.shape == (3, 3):
        c = np.broadcast_to(c, (n, 3, 3))
    elif c.shape != (n, 3, 3):
        raise InputError(
            f"{what} must be one 3x3 matrix (mm²) shared by all {count_name} or an array of shape ({n}, 3, 3), "
            f"got shape {c.shape}"
        )
    return _check_spd_stack(np.array(c), what)


def _weight_matrices(weights, n: int) -> np.ndarray:
    """Weights -> (n,3,3) matrices M_i = W_iᵀW_i, normalised to mean trace 3 (results are scale-invariant)."""
    if weights is None:
        return np.broadcast_to(np.eye(3), (n, 3, 3))
    w = _finite_array(weights, "weights")
    if w.shape == (n,):
        if np.any(w < 0):
            raise InputError("weights must be non-negative (one number per fiducial, e.g. 1/σ_i²)")
        m = w[:, None, None] * np.eye(3)
    elif w.shape == (n, 3, 3):
        m = _check_spd_stack(w.copy(), "weight matrices")
    else:
        raise InputError(
            f"weights must be None, one number per fiducial (shape ({n},)) or one 3x3 weight matrix per "
            f"fiducial (shape ({n}, 3, 3)), got shape {w.shape}"
        )
    total = np.trace(m, axis1=1, axis2=2).sum()
    if total <= 0:
        raise InputError("weights are all zero: at least three non-collinear fiducials need non-zero weight")
    return m * (3.0 * n / total)


def _design(x: np.ndarray) -> np.ndarray:
    """A(x) = [−[x]_× | I₃] for a stack of points (K,3) -> (K,3,6); A(x) p = δθ × x + δt."""
    k = len(x)
    a = np.zeros((k, 3, 6))
    # −[x]_× = [[0, z, −y], [−z, 0, x], [y, −x, 0]]
    a[:, 0, 1], a[:, 0, 2] = x[:, 2], -x[:, 1]
    a[:, 1, 0], a[:, 1, 2] = -x[:, 2], x[:, 0]
    a[:, 2, 0], a[:, 2, 1] = x[:, 1], -x[:, 0]
    a[:, :, 3:] = np.eye(3)
    return a


class _Linearised:
    """The linearised rigid fit over a fiducial set: centred/scaled design matrices, H and H⁻¹."""

    def __init__(self, fiducials: np.ndarray, m: np.ndarray):
        self.centroid = fiducials.mean(axis=0)
        xc = fiducials - self.centroid
        self.scale = float(np.sqrt(np.mean(np.sum(xc**2, axis=1))))
        if self.scale <= 0:
            raise InputError("fiducials all coincide: a rigid registration needs at least 3 non-collinear points")
        self.m = m
        self.a = _design(xc / self.scale)  # (N,3,6)
        h = np.einsum("nai,nab,nbj->ij", self.a, m, self.a)
        h = 0.5 * (h + h.T)
        evals, evecs = np.linalg.eigh(h)
        if not evals[-1] > 0 or evals[0] < _SINGULAR_RATIO * evals[-1]:
            raise InputError(
                "the fiducials do not determine a rigid transform (the normal matrix H is singular): they are "
                "collinear or nearly so, or the weights leave a direction unconstrained; add a fiducial off "
                "the line and give at least three non-collinear fiducials non-zero weight"
            )
        self.h_inv = (evecs / evals) @ evecs.T

    def design(self, points: np.ndarray) -> np.ndarray:
        return _design((points - self.centroid) / self.scale)


# --------------------------------------------------------------------------------------------------------
# simple metrics
# --------------------------------------------------------------------------------------------------------
def fre_rms(residuals) -> float:
    """Fiducial registration error: sqrt((1/N) Σ‖r_i‖²) of (N,3) residuals r_i = b_i − (R s_i + t), in mm."""
    r = _points(residuals, "residuals")
    return float(np.sqrt(np.mean(np.sum(r**2, axis=1))))


def tre(predicted, truth) -> np.ndarray:
    """Target registration errors ‖predicted_j − truth_j‖ (M,), mm; both (M,3) in the same frame."""
    p = _points(predicted, "predicted target positions", allow_empty=True)
    q = _points(truth, "true target positions", allow_empty=True)
    if p.shape != q.shape:
        raise InputError(
            f"predicted and true target positions must have the same shape (one row per target), got "
            f"{p.shape} and {q.shape}"
        )
    return np.linalg.norm(p - q, axis=1)


def _errors(errors) -> np.ndarray:
    e = _finite_array(errors, "target errors")
    if e.ndim != 1:
        raise InputError(
            f"target errors must be a 1-D array of distances (mm), got shape {e.shape}; "
            "for error vectors (M x 3) pass tre(predicted, truth) or their norms"
        )
    if len(e) == 0:
        raise InputError("target errors are empty: at least one target is needed")
    if np.any(e < 0):
        raise InputError("target errors are distances (mm) and cannot be negative; pass the output of tre()")
    return e


def rmst(errors) -> float:
    """Root mean square of target errors (M,) in mm: sqrt((1/M) Σ e_j²)."""
    e = _errors(errors)
    return float(np.sqrt(np.mean(e**2)))


def max_error(errors) -> float:
    """Largest target error (M,), mm."""
    return float(np.max(_errors(errors)))


# --------------------------------------------------------------------------------------------------------
# error prediction
# --------------------------------------------------------------------------------------------------------
def expected_fre_squared(n, fle_rms) -> float:
    """<FRE²> ≈ (1 − 2/N) <FLE²> (mm²) for N fiducials, isotropic homogeneous FLE in 3-D, uniform weights.

    Fitzpatrick, West & Maurer 1998; the 2/N is the 6 fitted parameters out of 3N coordinates. `fle_rms` is
    sqrt(<FLE²>) of the net two-frame FLE (mm).
    """
    try:
        n_int = int(n)
    except (TypeError, ValueError):
        raise InputError(f"the number of fiducials must be an integer, got {n!r}") from None
    if n_int != n or n_int < 3:
        raise InputError(f"the number of fiducials must be an integer >= 3, got {n!r}")
    f = _scalar(fle_rms, "fle_rms")
    return (1.0 - 2.0 / n_int) * f**2


def expected_tre_fitzpatrick(fiducials, targets, fle_rms) -> np.ndarray:
    """RMS target registration error sqrt(<TRE²(r)>) (M,) in mm, Fitzpatrick, West & Maurer 1998, eq. 46:

        <TRE²(r)> ≈ <FLE²>/N · (1 + (1/3) Σ_{k=1..3} d_k² / f_k²)

    fiducials: (N,3) in the frame the registration maps into (mm); targets: (M,3) in the same frame.
    fle_rms: sqrt(<FLE²>) of the net two-frame FLE (mm, §0: 3σ_s² + 3σ_b² for isotropic noise).
    Assumptions: isotropic, homogeneous, independent FLE; uniform weights; first order in FLE/f.

    With X_c = X − mean(X) = U Λ Vᵀ: f_k² = Σ_{j≠k} λ_j² / N (mean squared distance of the fiducials from
    principal axis k) and d_k² = Σ_{j≠k} u_j² with u = Vᵀ(r − mean(X)) (squared distance of r from axis k).
    Coplanar fiducials (λ_3 = 0) are fine: f for each in-plane axis then comes from the other in-plane spread
    only. Collinear or coincident fiducials (some f_k = 0) raise InputError.
    """
    x = _fiducials(fiducials)
    r = _points(targets, "targets", allow_empty=True)
    fle = _scalar(fle_rms, "fle_rms")
    n = len(x)
    c = x.mean(axis=0)
    _, lam, vt = np.linalg.svd(x - c, full_matrices=False)
    lam2 = lam**2
    f2 = (lam2.sum() - lam2) / n
    if not f2.max() > 0 or f2.min() < _SINGULAR_RATIO * f2.max():
        raise InputError(
            "the fiducials are collinear or coincide (a principal spread f_k is zero), so the rotation about "
            "their line is undetermined; add a fiducial off the line"
        )
    u = (r - c) @ vt.T  # (M,3) coordinates along the principal axes
    u2 = u**2
    d2 = u2.sum(axis=1, keepdims=True) - u2
    tre2 = fle**2 / n * (1.0 + np.sum(d2 / f2, axis=1) / 3.0)
    return np.sqrt(tre2)


def tre_covariance_first_order(fiducials, targets, fle_cov, weights=None, target_cov=None) -> np.ndarray:
    """First-order covariance of TRE (M,3,3), mm², Danilchenko & Fitzpatrick 2011 (docs/theory.md §2.3).

    fiducials: (N,3) true fiducial positions in the destination (robot) frame, mm.
    targets: (M,3) in the same frame, mm.
    fle_cov: net two-space FLE covariance in the destination frame (mm²), one (3,3) shared by all fiducials
        or (N,3,3) one per fiducial: Σ_i = R Σ_s,i Rᵀ + Σ_b,i (sensor-side covariance rotated by the
        sensor-to-robot rotation R, plus the robot-side covariance).
    weights: the registration's weights: None (uniform), (N,) scalars w_i (M_i = w_i I), or (N,3,3) weight
        matrices M_i = W_iᵀW_i (destination frame). Only relative weights matter.
    target_cov: optional (3,3) or (M,3,3) target localisation covariance in the destination frame (mm²),
        added to the result (e.g. R Σ_s(r) Rᵀ for a target measured by the sensor).

    With A(x) = [−[x]_× | I₃] and A_i = A(x_i):
        H = Σ A_iᵀ M_i A_i,   B = Σ A_iᵀ M_i Σ_i M_i A_i,   Cov(p) = H⁻¹ B H⁻¹,
        Cov(TRE(r)) = A(r) Cov(p) A(r)ᵀ (+ target_cov).
    <TRE²(r)> is the trace; with isotropic Σ_i = (FLE²/3) I and uniform weights the trace equals
    expected_tre_fitzpatrick(...)² exactly. Computed about the fiducial centroid, scaled by the RMS radius.
    """
    x = _fiducials(fiducials)
    r = _points(targets, "targets", allow_empty=True)
    n, m_count = len(x), len(r)
    sig = _cov_stack(fle_cov, n, "fle_cov", "fiducials")
    lin = _Linearised(x, _weight_matrices(weights, n))
    ma = np.einsum("nab,nbj->naj", lin.m, lin.a)  # M_i A_i
    b = np.einsum("nai,nab,nbj->ij", ma, sig, ma)
    cov_p = lin.h_inv @ b @ lin.h_inv
    cov_p = 0.5 * (cov_p + cov_p.T)
    ar = lin.design(r)
    out = np.einsum("mai,ij,mbj->mab", ar, cov_p, ar)
    if target_cov is not None:
        out = out + _cov_stack(target_cov, m_count, "target_cov", "targets")
    return 0.5 * (out + np.swapaxes(out, 1, 2))


def bias_tre(fiducials, targets, bias_at_fiducials, bias_at_targets, weights=None) -> np.ndarray:
    """Deterministic (bias) part of TRE (M,3), mm, to first order (docs/theory.md §2.3):

        TRE_bias(r) = β(r) − A(r) H⁻¹ Σ_i A_iᵀ M_i β(x_i),   H = Σ A_iᵀ M_i A_i.

    β is a systematic error field in the destination frame with the same sign as the net FLE δ = R ε − η:
    the mapped sensor point minus the robot point, before the fit. bias_at_fiducials: (N,3) β(x_i);
    bias_at_targets: (M,3) β(r_j) (a target that shares the field, e.g. measured by the same sensor and
    executed by the same arm). fiducials (N,3) and targets (M,3): destination frame, mm. weights as in
    tre_covariance_first_order. The rigid fit absorbs the field's weighted least-squares rigid projection;
    what remains is the floor no rigid registration removes. An infinitesimal rigid motion β(x) = ω × x + τ
    gives exactly zero.
    """
    x = _fiducials(fiducials)
    r = _points(targets, "targets", allow_empty=True)
    bf = _points(bias_at_fiducials, "bias_at_fiducials")
    bt = _points(bias_at_targets, "bias_at_targets", allow_empty=True)
    if bf.shape != x.shape:
        raise InputError(f"bias_at_fiducials must have one row per fiducial, shape {x.shape}, got {bf.shape}")
    if bt.shape != r.shape:
        raise InputError(f"bias_at_targets must have one row per target, shape {r.shape}, got {bt.shape}")
    lin = _Linearised(x, _weight_matrices(weights, len(x)))
    g = np.einsum("nai,nab,nb->i", lin.a, lin.m, bf)
    dp = lin.h_inv @ g
    return bt - lin.design(r) @ dp
