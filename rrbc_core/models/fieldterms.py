"""Error terms for effects estimated from measurements (`errormodels.ErrorTerm`): `sampled_field`, a fixed smooth
field through measured values; `field_uncertainty`, what such a field's estimate does not know (a Gaussian
process's posterior); and `linear_uncertainty`, what a least-squares fit of a linear map of position and a drift
does not know (its coefficients' covariance). What `rrbc check-model` writes for what it measured
(docs/check_model.md)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.models.errormodels import PointSet, _check_trials, _number, _set, _Term, _vector

__all__ = ["LINEAR_BASES", "MAX_FIELD_SAMPLES", "FieldUncertainty", "LinearUncertainty", "SampledField"]

MAX_FIELD_SAMPLES = 2000  # points of a sampled field: its solve is O(M³) once, its evaluation O(P·M)
#: `linear_uncertainty`'s bases -> their columns after the constant: position (x, y, z about center_mm), time (t − t0_s)
LINEAR_BASES = {"position": 3, "time": 1, "position_time": 4}


@dataclass(frozen=True)
class SampledField(_Term):
    """A fixed smooth vector field known at points (mm), in the side's frame: displacement at x is
    Σ_j k(x, p_j) α_j with k(x, p) = exp(−|x − p|²/(2 length_mm²)) and α the solution of (K + 1e-6·I) α = vectors_mm,
    K_ij = k(p_i, p_j): the smooth interpolant through (`points_mm`, `vectors_mm`), going to zero far from them (a
    Gaussian process's mean). What `rrbc check-model` writes for a smooth field it measured (docs/check_model.md).
    `points_mm` and `vectors_mm`: lists of [x, y, z], the same length, 1 to 2000. Either side.
    """

    points_mm: tuple
    vectors_mm: tuple
    length_mm: float
    kind: ClassVar[str] = "sampled_field"
    random: ClassVar[bool] = False
    _alpha: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        pts = _samples("points_mm", self.points_mm)
        vec = _samples("vectors_mm", self.vectors_mm)
        if len(pts) != len(vec):
            raise InputError(f"points_mm has {len(pts)} points but vectors_mm {len(vec)} vectors: one per point")
        _set(self, "length_mm", _number("length_mm", self.length_mm, positive=True, unit="mm"))
        _set(self, "points_mm", tuple(tuple(float(v) for v in p) for p in pts))
        _set(self, "vectors_mm", tuple(tuple(float(v) for v in p) for p in vec))
        kmat = self._kernel(pts)
        alpha = np.linalg.solve(kmat + 1e-6 * np.eye(len(pts)), vec)
        alpha.setflags(write=False)
        _set(self, "_alpha", alpha)

    def _kernel(self, x: np.ndarray) -> np.ndarray:
        p = np.asarray(self.points_mm, float)
        d2 = np.sum((x[:, None, :] - p[None]) ** 2, axis=-1)
        return np.exp(-d2 / (2.0 * self.length_mm**2))

    def field(self, x) -> np.ndarray:
        """The field at points x (P, 3) mm -> (P, 3) mm."""
        xa = np.atleast_2d(np.asarray(x, dtype=float))
        out = np.empty(xa.shape)
        step = 1024  # bounded memory: (step, M, 3) at a time
        for i in range(0, len(xa), step):
            out[i : i + step] = self._kernel(xa[i : i + step]) @ self._alpha
        return out

    def sample(self, points: PointSet, side: str, rng: np.random.Generator, trials: int) -> np.ndarray:
        _check_trials(trials)
        return self.field(points.frame(self._side(side)))[None]


@dataclass(frozen=True)
class FieldUncertainty(_Term):
    """How uncertain a `sampled_field` is (random, redrawn every trial): a zero-mean Gaussian process whose
    covariance is the posterior covariance of a field with prior variance `field_var_mm2` (3,) per axis and
    correlation exp(−|r|²/(2 length_mm²)), measured at `points_mm` with noise variance `noise_var_mm2`:

        Σ_a(x, x') = v_a [k(x, x') − k(x, P) (K + (σ²/v_a) I)⁻¹ k(P, x')]

    small near the points, the prior's far from them. Draws are correlated over the points of one call (a joint
    draw, O(P³) for P points; at most 5000 points per call). What `rrbc check-model` writes beside a measured field,
    so that a prediction holds what the field's estimate does not know. Either side.
    """

    points_mm: tuple
    length_mm: float
    field_var_mm2: tuple
    noise_var_mm2: float
    kind: ClassVar[str] = "field_uncertainty"
    random: ClassVar[bool] = True
    _solves: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        pts = _samples("points_mm", self.points_mm)
        _set(self, "points_mm", tuple(tuple(float(v) for v in p) for p in pts))
        _set(self, "length_mm", _number("length_mm", self.length_mm, positive=True, unit="mm"))
        _set(self, "field_var_mm2", _vector("field_var_mm2", self.field_var_mm2, 3, minimum=0, unit="mm²"))
        _set(self, "noise_var_mm2", _number("noise_var_mm2", self.noise_var_mm2, positive=True, unit="mm²"))
        kmat = _gauss(pts, pts, self.length_mm)
        solves = []
        for v in self.field_var_mm2:
            ratio = self.noise_var_mm2 / v if v > 0 else np.inf
            solves.append(None if not np.isfinite(ratio) else np.linalg.inv(kmat + ratio * np.eye(len(pts))))
        _set(self, "_solves", tuple(solves))

    def _axis_cov(self, x: np.ndarray, a: int, diagonal: bool) -> np.ndarray:
        v = self.field_var_mm2[a]
        inv = self._solves[a]
        if inv is None:
            return np.zeros(len(x)) if diagonal else np.zeros((len(x), len(x)))
        kx = _gauss(x, np.asarray(self.points_mm), self.length_mm)
        if diagonal:
            return v * np.clip(1.0 - np.einsum("ij,jk,ik->i", kx, inv, kx), 0.0, None)
        return v * (_gauss(x, x, self.length_mm) - kx @ inv @ kx.T)

    def covariance(self, points) -> np.ndarray:
        """Per-point covariance (P, 3, 3) mm² (diagonal: the axes are independent) at points (P, 3)."""
        x = np.atleast_2d(np.asarray(points, float))
        out = np.zeros((len(x), 3, 3))
        for a in range(3):
            out[:, a, a] = self._axis_cov(x, a, True)
        return out

    def sample(self, points: PointSet, side: str, rng: np.random.Generator, trials: int) -> np.ndarray:
        x = points.frame(self._side(side))
        n = len(x)
        if n > 5000:
            raise InputError(f"field_uncertainty draws at most 5000 points at once, got {n}")
        out = np.zeros((_check_trials(trials), n, 3))
        for a in range(3):
            cov = self._axis_cov(x, a, False)
            w, vec = np.linalg.eigh(0.5 * (cov + cov.T))
            root = vec * np.sqrt(np.clip(w, 0.0, None))
            out[:, :, a] = rng.standard_normal((trials, n)) @ root.T
        return out


@dataclass(frozen=True)
class LinearUncertainty(_Term):
    """How uncertain a fitted linear term is (random, redrawn every trial): per axis a, the displacement
    φ(x, t) · c_a with φ = [1, x − center_mm, t − t0_s] (the columns `basis` names: "position" [1, x, y, z],
    "time" [1, t], "position_time" [1, x, y, z, t]) and coefficients c_a ~ N(0, var_mm2[a] · design_inverse):
    the covariance of least-squares coefficients, `design_inverse` = (ΦᵀΦ)⁻¹ of the fit's design (k x k, k the
    columns; units mm⁻² and s⁻² as the columns') and `var_mm2` (3,) the fit's residual variance per axis. What
    `rrbc check-model` writes beside an `affine` or `drift` term it fitted, so that a prediction holds what the fit
    does not know (docs/check_model.md). One draw per trial is shared by the points of one call. Either side.
    """

    basis: str
    center_mm: tuple[float, float, float]
    t0_s: float
    design_inverse: tuple
    var_mm2: tuple[float, float, float]
    kind: ClassVar[str] = "linear_uncertainty"
    random: ClassVar[bool] = True
    _root: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        if self.basis not in LINEAR_BASES:
            raise InputError(f"basis must be one of {', '.join(LINEAR_BASES)}, got {self.basis!r}")
        k = LINEAR_BASES[self.basis] + 1
        _set(self, "center_mm", _vector("center_mm", self.center_mm, 3, unit="mm"))
        _set(self, "t0_s", _number("t0_s", self.t0_s, unit="s", limit=1e11))
        _set(self, "var_mm2", _vector("var_mm2", self.var_mm2, 3, minimum=0, unit="mm²"))
        rows = self.design_inverse
        if isinstance(rows, (str, bytes, dict)) or not hasattr(rows, "__len__") or len(rows) != k:
            raise InputError(f"design_inverse must be a {k}x{k} matrix for basis {self.basis!r}, got {rows!r}")
        mat = np.array([_vector(f"design_inverse[{i}]", r, k) for i, r in enumerate(rows)])
        if not np.allclose(mat, mat.T, rtol=1e-6, atol=1e-15):
            raise InputError("design_inverse must be symmetric (the inverse of a least-squares fit's ΦᵀΦ)")
        w, vec = np.linalg.eigh(mat)
        if w[0] < -1e-9 * max(abs(w[-1]), 1e-300):
            raise InputError("design_inverse must be positive semi-definite (the inverse of a fit's ΦᵀΦ)")
        _set(self, "design_inverse", tuple(tuple(float(v) for v in r) for r in mat))
        root = vec * np.sqrt(np.clip(w, 0.0, None))
        root.setflags(write=False)
        _set(self, "_root", root)

    def design(self, points: PointSet, side: str) -> np.ndarray:
        """The columns φ at the points: (P, k)."""
        x = points.frame(self._side(side))
        cols = [np.ones((len(x), 1))]
        if self.basis != "time":
            cols.append(x - np.asarray(self.center_mm))
        if self.basis != "position":
            cols.append((np.asarray(points.time, float) - self.t0_s)[:, None])
        return np.hstack(cols)

    def covariance(self, points: PointSet, side: str = "robot") -> np.ndarray:
        """Per-point covariance (P, 3, 3) mm² (diagonal: the axes' fits are independent)."""
        phi = self.design(points, side)
        q = np.einsum("pi,ij,pj->p", phi, np.asarray(self.design_inverse), phi)
        return q[:, None, None] * (np.asarray(self.var_mm2)[None, :, None] * np.eye(3)[None])

    def sample(self, points: PointSet, side: str, rng: np.random.Generator, trials: int) -> np.ndarray:
        phi = self.design(points, side)
        coef = rng.standard_normal((_check_trials(trials), 3, phi.shape[1])) @ self._root.T  # (T, 3, k)
        coef *= np.sqrt(np.asarray(self.var_mm2))[None, :, None]
        return np.einsum("pk,tak->tpa", phi, coef)


def _gauss(x: np.ndarray, p: np.ndarray, length: float) -> np.ndarray:
    d2 = np.sum((x[:, None, :] - p[None]) ** 2, axis=-1)
    return np.exp(-d2 / (2.0 * length**2))


def _samples(name: str, value) -> np.ndarray:
    """(M, 3) finite floats from a list of [x, y, z], 1 <= M <= MAX_FIELD_SAMPLES."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a list of [x, y, z] numbers (mm)") from None
    if arr.ndim != 2 or arr.shape[1] != 3 or not 1 <= len(arr) <= MAX_FIELD_SAMPLES:
        raise InputError(
            f"{name} must be a list of 1 to {MAX_FIELD_SAMPLES} [x, y, z] triples (mm), got shape {arr.shape}"
        )
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} holds a value that is not a finite number")
    return arr
