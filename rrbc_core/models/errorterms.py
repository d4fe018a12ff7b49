"""The error terms (`errormodels.ErrorTerm`): noise — isotropic, anisotropic along the line of sight, growing with range —
and outliers (random, redrawn every trial); scale, affine, smooth field, the arm's kinematic (DH) error, drift and
warm-up (deterministic: bias). And the error model's table form, as scene files and reports write it."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.models.arm_masses import dh_chain_with_masses
from rrbc_core.models.dh_table import _dh_table, _dh_value
from rrbc_core.models.errormodels import (
    SIDES,
    TERM_TYPES,
    ErrorModel,
    ErrorTerm,
    PointSet,
    _check_trials,
    _integer,
    _matrix3,
    _number,
    _set,
    _Term,
    _vector,
)
from rrbc_core.models.kinematics import UR5, UR5_TOOL_DOWN_SEED, DHParameters, forward, inverse_path, perturbed
from rrbc_core.models.loads import gravity_loads

_FIELD_CHUNK = 8192  # points per block when evaluating a smooth field


def _unit_vectors(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit viewing directions (P, 3) and ranges (P,) mm of sensor-frame points (P, 3)."""
    rho = np.linalg.norm(x, axis=-1)
    bad = np.flatnonzero(rho <= 1e-9)
    if bad.size:
        raise InputError(f"point {bad[0]} is at the sensor origin: it has no viewing direction for anisotropic noise")
    return x / rho[:, None], rho


def _anisotropic_covariance(x, sigma_perp, sigma_along) -> np.ndarray:
    """Σ = σ_along² u uᵀ + σ_perp² (I − u uᵀ) per point; sigmas scalar or (P,)."""
    u, _ = _unit_vectors(x)
    uu = u[:, :, None] * u[:, None, :]
    sp = np.broadcast_to(np.asarray(sigma_perp, dtype=float), (len(x),))[:, None, None]
    sa = np.broadcast_to(np.asarray(sigma_along, dtype=float), (len(x),))[:, None, None]
    return sa**2 * uu + sp**2 * (np.eye(3) - uu)


def _anisotropic_sample(x, sigma_perp, sigma_along, rng, trials) -> np.ndarray:
    """z ~ N(0, I); displacement = σ_perp z + (σ_along − σ_perp)(u·z) u, whose covariance is Σ above."""
    u, _ = _unit_vectors(x)
    z = rng.standard_normal((trials, len(x), 3))
    sp = np.broadcast_to(np.asarray(sigma_perp, dtype=float), (len(x),))
    sa = np.broadcast_to(np.asarray(sigma_along, dtype=float), (len(x),))
    along = np.einsum("tpi,pi->tp", z, u)
    return sp[None, :, None] * z + ((sa - sp)[None, :] * along)[..., None] * u[None]


# --- random terms ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class IsotropicNoise(_Term):
    """Gaussian noise, sigma_mm (mm, 1 sigma) on each axis, independent between points and trials. Either side."""

    sigma_mm: float
    kind: ClassVar[str] = "isotropic_noise"
    random: ClassVar[bool] = True

    def __post_init__(self):
        _set(self, "sigma_mm", _number("sigma_mm", self.sigma_mm, minimum=0, unit="mm"))

    def covariance(self, points) -> np.ndarray:
        """Covariance (P, 3, 3) mm² for points (P, 3) (any frame): σ² I."""
        n = len(np.atleast_2d(points))
        return np.broadcast_to(self.sigma_mm**2 * np.eye(3), (n, 3, 3)).copy()

    def sample(self, points: PointSet, side: str, rng: np.random.Generator, trials: int) -> np.ndarray:
        self._side(side)
        return rng.normal(0.0, self.sigma_mm, (_check_trials(trials), len(points), 3))


@dataclass(frozen=True)
class AnisotropicNoise(_Term):
    """Gaussian sensor noise with covariance Σ = σ_along² u uᵀ + σ_perp² (I − u uᵀ), u the unit vector from the
    sensor (origin of the sensor frame) to the point; sigmas in mm. Sensor side only."""

    sigma_perp_mm: float
    sigma_along_mm: float
    kind: ClassVar[str] = "anisotropic_noise"
    random: ClassVar[bool] = True
    sides: ClassVar[tuple[str, ...]] = ("sensor",)

    def __post_init__(self):
        _set(self, "sigma_perp_mm", _number("sigma_perp_mm", self.sigma_perp_mm, minimum=0, unit="mm"))
        _set(self, "sigma_along_mm", _number("sigma_along_mm", self.sigma_along_mm, minimum=0, unit="mm"))

    def covariance(self, points_sensor) -> np.ndarray:
        """Covariance (P, 3, 3) mm² at sensor-frame points (P, 3) mm."""
        x = np.atleast_2d(np.asarray(points_sensor, float))
        return _anisotropic_covariance(x, self.sigma_perp_mm, self.sigma_along_mm)

    def sample(self, points: PointSet, side: str, rng: np.random.Generator, trials: int) -> np.ndarray:
        self._side(side)
        return _anisotropic_sample(points.sensor, self.sigma_perp_mm, self.sigma_along_mm, rng, _check_trials(trials))


@dataclass(frozen=True)
class RangeNoise(_Term):
    """Anisotropic sensor noise whose sigmas grow with the range ρ (metres) from the sensor:

        σ_⊥(ρ) = perp_mm[0] + perp_mm[1]·ρ                         (mm; c0 mm, c1 mm/m)
        σ_∥(ρ) = along_mm[0] + along_mm[1]·ρ + along_mm[2]·ρ²       (mm; c0 mm, c1 mm/m, c2 mm/m²)

    with Σ = σ_∥² u uᵀ + σ_⊥² (I − u uᵀ) as in `AnisotropicNoise`. Linear terms model a laser tracker, the
    quadratic depth term a stereo camera (`laser_tracker`, `stereo`). Sensor side only. Coefficients >= 0.
    """

    perp_mm: tuple[float, float]
    along_mm: tuple[float, float, float]
    kind: ClassVar[str] = "range_noise"
    random: ClassVar[bool] = True
    sides: ClassVar[tuple[str, ...]] = ("sensor",)

    def __post_init__(self):
        _set(self, "perp_mm", _vector("perp_mm", self.perp_mm, 2, minimum=0, unit="c0 mm, c1 mm/m"))
        _set(self, "along_mm", _vector("along_mm", self.along_mm, 3, minimum=0, unit="c0 mm, c1 mm/m, c2 mm/m²"))

    @classmethod
    def laser_tracker(cls) -> RangeNoise:
        """Typical (half-MPE) laser-tracker noise, docs/theory.md §5.2: σ_∥ = (10 µm + 0.3 µm/m·ρ)/2,
        σ_⊥ = (15 µm + 6 µm/m·ρ)/2."""
        return cls(perp_mm=(0.0075, 0.003), along_mm=(0.005, 0.00015, 0.0))

    @classmethod
    def stereo(cls, focal_px: float, baseline_m: float, sigma_disparity_px: float, sigma_pixel_px: float) -> RangeNoise:
        """Stereo camera, docs/theory.md §5.2: σ_∥ = ρ² σ_d/(f B), σ_⊥ = ρ σ_u/f (ρ in m, result in mm)."""
        f = _number("focal_px", focal_px, positive=True, unit="px")
        b = _number("baseline_m", baseline_m, positive=True, unit="m")
        sd = _number("sigma_disparity_px", sigma_disparity_px, minimum=0, unit="px")
        su = _number("sigma_pixel_px", sigma_pixel_px, minimum=0, unit="px")
        return cls(perp_mm=(0.0, 1000.0 * su / f), along_mm=(0.0, 0.0, 1000.0 * sd / (f * b)))

    def sigmas(self, points_sensor) -> tuple[np.ndarray, np.ndarray]:
        """(σ_⊥, σ_∥), each (P,) mm, at sensor-frame points (P, 3) mm."""
        rho_m = np.linalg.norm(np.atleast_2d(np.asarray(points_sensor, float)), axis=-1) / 1000.0
        p0, p1 = self.perp_mm
        a0, a1, a2 = self.along_mm
        return p0 + p1 * rho_m, a0 + a1 * rho_m + a2 * rho_m**2

    def covariance(self, points_sensor) -> np.ndarray:
        """Covariance (P, 3, 3) mm² at sensor-frame points (P, 3) mm."""
        x = np.atleast_2d(np.asarray(points_sensor, float))
        return _anisotropic_covariance(x, *self.sigmas(x))

    def sample(self, points: PointSet, side: str, rng: np.random.Generator, trials: int) -> np.ndarray:
        self._side(side)
        return _anisotropic_sample(points.sensor, *self.sigmas(points.sensor), rng, _check_trials(trials))


@dataclass(frozen=True)
class Outliers(_Term):
    """Gross errors: in every trial each point independently, with probability `fraction`, is displaced by
    `size_mm` (mm) in a uniformly random direction. Either side."""

    fraction: float
    size_mm: float
    kind: ClassVar[str] = "outliers"
    random: ClassVar[bool] = True

    def __post_init__(self):
        f = _number("fraction", self.fraction, minimum=0)
        if f > 1:
            raise InputError(f"fraction must be between 0 and 1 (a probability), got {self.fraction!r}")
        _set(self, "fraction", f)
        _set(self, "size_mm", _number("size_mm", self.size_mm, minimum=0, unit="mm"))

    def covariance(self, points) -> np.ndarray:
        """Covariance (P, 3, 3) mm² (mean zero, isotropic): fraction · size² / 3 · I. Not Gaussian."""
        n = len(np.atleast_2d(points))
        return np.broadcast_to(self.fraction * self.size_mm**2 / 3.0 * np.eye(3), (n, 3, 3)).copy()

    def sample(self, points: PointSet, side: str, rng: np.random.Generator, trials: int) -> np.ndarray:
        self._side(side)
        t = _check_trials(trials)
        hit = rng.random((t, len(points))) < self.fraction
        d = rng.standard_normal((t, len(points), 3))
        d /= np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-300)
        return np.where(hit[..., None], self.size_mm * d, 0.0)


# --- deterministic terms -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Scale(_Term):
    """Scale error: displacement = (ppm + ppm_per_s·(t − t0_s))·1e-6·(x − center_mm), x in the side's frame (mm), t
    the point's time (s): a constant scale, or one that changes with time (a thermal ramp). Either side."""

    ppm: float
    center_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    ppm_per_s: float = 0.0
    t0_s: float = 0.0
    kind: ClassVar[str] = "scale"
    random: ClassVar[bool] = False

    def __post_init__(self):
        _set(self, "ppm", _number("ppm", self.ppm, unit="parts per million"))
        _set(self, "center_mm", _vector("center_mm", self.center_mm, 3, unit="mm"))
        _set(self, "ppm_per_s", _number("ppm_per_s", self.ppm_per_s, unit="parts per million per second"))
        _set(self, "t0_s", _number("t0_s", self.t0_s, unit="s", limit=1e11))

    def sample(self, points: PointSet, side: str, rng: np.random.Generator, trials: int) -> np.ndarray:
        x = points.frame(self._side(side))
        _check_trials(trials)
        ppm = self.ppm + self.ppm_per_s * (np.asarray(points.time, float) - self.t0_s)
        return (ppm[:, None] * 1e-6 * (x - np.asarray(self.center_mm)))[None]


@dataclass(frozen=True)
class Affine(_Term):
    """Linear distortion: displacement = G (x − center_mm), G = `matrix` (3x3, mm/mm: per-axis scale on the
    diagonal, shear off it), x in the side's frame (mm). Either side."""

    matrix: tuple[tuple[float, float, float], ...]
    center_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    kind: ClassVar[str] = "affine"
    random: ClassVar[bool] = False

    def __post_init__(self):
        m = self.matrix.tolist() if isinstance(self.matrix, np.ndarray) else self.matrix
        _set(self, "matrix", _matrix3("matrix", m))
        _set(self, "center_mm", _vector("center_mm", self.center_mm, 3, unit="mm"))

    def sample(self, points: PointSet, side: str, rng: np.random.Generator, trials: int) -> np.ndarray:
        x = points.frame(self._side(side))
        _check_trials(trials)
        return ((x - np.asarray(self.center_mm)) @ np.asarray(self.matrix).T)[None]


@dataclass(frozen=True)
class SmoothField(_Term):
    """A smooth random vector field β(x) (mm) in the side's frame: one sample of a zero-mean stationary Gaussian
    process whose three components are independent with correlation exp(−|r|²/(2 length_mm²)).

    Realised with `features` random Fourier features drawn from np.random.default_rng(seed) (Rahimi & Recht):
    β(x) = rms_mm/√3 · √(2/M) · Σ_j w_j cos(ω_j·x + b_j), ω_j ~ N(0, I/length²), b_j ~ U(0, 2π),
    w_j ~ N(0, I₃). Then E|β(x)|² = rms_mm² exactly at every x (expectation over the draw). The same seed gives
    the same field. Either side.
    """

    rms_mm: float
    length_mm: float
    seed: int
    features: int = 256
    kind: ClassVar[str] = "smooth_field"
    random: ClassVar[bool] = False
    # the random Fourier features, drawn in __post_init__ from `seed` (not fields: derived, read-only)
    _omega: np.ndarray = field(init=False, repr=False, compare=False)
    _phase: np.ndarray = field(init=False, repr=False, compare=False)
    _weights: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        _set(self, "rms_mm", _number("rms_mm", self.rms_mm, minimum=0, unit="mm"))
        _set(self, "length_mm", _number("length_mm", self.length_mm, positive=True, unit="mm"))
        _set(self, "seed", _integer("seed", self.seed))
        _set(self, "features", _integer("features", self.features, minimum=1))
        rng = np.random.default_rng(self.seed)
        m = self.features
        omega = rng.standard_normal((m, 3)) / self.length_mm
        phase = rng.uniform(0.0, 2 * np.pi, m)
        weights = rng.standard_normal((m, 3)) * (self.rms_mm / np.sqrt(3.0) * np.sqrt(2.0 / m))
        for name, v in (("_omega", omega), ("_phase", phase), ("_weights", weights)):
            v.setflags(write=False)
            _set(self, name, v)

    def field(self, x) -> np.ndarray:
        """β at points x (P, 3) mm -> (P, 3) mm."""
        xa = np.atleast_2d(np.asarray(x, dtype=float))
        if xa.shape[-1] != 3:
            raise InputError(f"points must have 3 coordinates, got shape {xa.shape}")
        out = np.empty(xa.shape)
        for i in range(0, len(xa), _FIELD_CHUNK):  # bounded memory: (chunk, features) at a time
            out[i : i + _FIELD_CHUNK] = np.cos(xa[i : i + _FIELD_CHUNK] @ self._omega.T + self._phase) @ self._weights
        return out

    def sample(self, points: PointSet, side: str, rng: np.random.Generator, trials: int) -> np.ndarray:
        _check_trials(trials)
        return self.field(points.frame(self._side(side)))[None]


def _arm_joints(kind: str, dh: DHParameters, points: PointSet) -> np.ndarray:
    """Joint angles (P, 6) rad that put arm `dh` at the physical points with their tool rotations (IK seeded by
    points.joint_seed, default `UR5_TOOL_DOWN_SEED`), for the error term `kind`."""
    if points.tool_rotation is None:
        raise InputError(
            f"the {kind} error term needs the tool orientation at each point (PointSet.tool_rotation): "
            "the error depends on the joint configuration, not only on the position"
        )
    seed = UR5_TOOL_DOWN_SEED if points.joint_seed is None else points.joint_seed
    try:
        return inverse_path(dh, points.robot, points.tool_rotation, seed)
    except InputError as e:
        raise InputError(f"{kind} error term: {e}") from None


@dataclass(frozen=True)
class Kinematic(_Term):
    """Robot kinematic (DH) error, robot side only (docs/theory.md §5.1).

    The true robot is `perturbed(dh, np.random.default_rng(seed), joint_offset_deg, link_mm, twist_deg)`. For a
    physical point p (robot frame, mm) reached with tool rotation R_p, the true robot's joints q solve
    forward(true, q) = (p, R_p) (IK seeded by points.joint_seed, default `UR5_TOOL_DOWN_SEED`); the robot
    reports forward(dh, q). Displacement = reported − p (mm). It depends on the joint configuration, so the
    same point reached with another tool orientation has another error. `dh` may be given as "UR5" or a table
    (any of a, d, alpha, theta_offset, tool_mm; the rest from UR5), e.g. {"tool_mm": 100} for a 100 mm stylus.
    """

    seed: int
    joint_offset_deg: float = 0.1
    link_mm: float = 0.2
    twist_deg: float = 0.05
    dh: DHParameters = field(default=UR5)
    kind: ClassVar[str] = "kinematic"
    random: ClassVar[bool] = False
    sides: ClassVar[tuple[str, ...]] = ("robot",)

    def __post_init__(self):
        _set(self, "seed", _integer("seed", self.seed))
        _set(self, "joint_offset_deg", _number("joint_offset_deg", self.joint_offset_deg, minimum=0, unit="deg"))
        _set(self, "link_mm", _number("link_mm", self.link_mm, minimum=0, unit="mm"))
        _set(self, "twist_deg", _number("twist_deg", self.twist_deg, minimum=0, unit="deg"))
        _set(self, "dh", _dh_value(self.dh))

    def true_robot(self) -> DHParameters:
        """The perturbed ("true") DH parameters this term stands for."""
        return perturbed(self.dh, np.random.default_rng(self.seed), self.joint_offset_deg, self.link_mm, self.twist_deg)

    def joints(self, points: PointSet) -> np.ndarray:
        """Joint angles (P, 6) rad of the true robot at the physical points."""
        return _arm_joints(self.kind, self.true_robot(), points)

    def displacement(self, points: PointSet) -> np.ndarray:
        """Reported minus physical position (P, 3) mm, robot frame."""
        reported, _ = forward(self.dh, self.joints(points))
        return reported - points.robot

    def sample(self, points: PointSet, side: str, rng: np.random.Generator, trials: int) -> np.ndarray:
        self._side(side)
        _check_trials(trials)
        return self.displacement(points)[None]


@dataclass(frozen=True)
class Compliance(_Term):
    """Joint compliance under gravity load (module docstring): `joints_rad_per_Nm` (6,) per joint, `payload_kg` at
    the tool point, `dh` the arm (as for `kinematic`: "UR5" or a table)."""

    joints_rad_per_Nm: tuple = (0.0, 3e-5, 2e-5, 0.0, 0.0, 0.0)
    payload_kg: float = 0.0
    dh: DHParameters = field(default=UR5)
    kind: ClassVar[str] = "compliance"
    random: ClassVar[bool] = False
    sides: ClassVar[tuple[str, ...]] = ("robot",)

    def __post_init__(self):
        _set(self, "joints_rad_per_Nm", _vector("joints_rad_per_Nm", self.joints_rad_per_Nm, 6, minimum=0.0))
        _set(self, "payload_kg", _number("payload_kg", self.payload_kg, minimum=0, unit="kg"))
        _set(self, "dh", _dh_value(self.dh))
        if max(self.joints_rad_per_Nm) > 1e-3:
            raise InputError("joints_rad_per_Nm: at most 1e-3 rad/Nm per joint (real arms: 1e-6 to 1e-4)")

    def joints(self, points: PointSet) -> np.ndarray:
        """The joints (P, 6) rad the controller reads at the physical points: the arm's pose there less its
        deflection under the load, q − c τ(q)."""
        q = _arm_joints(self.kind, self.dh, points)
        tau = gravity_loads(dh_chain_with_masses(self.dh, self.payload_kg), q).torque
        return q - np.asarray(self.joints_rad_per_Nm) * tau

    def displacement(self, points: PointSet) -> np.ndarray:
        """Reported minus physical position (P, 3) mm, robot frame."""
        return forward(self.dh, self.joints(points))[0] - points.robot

    def sample(self, points: PointSet, side: str, rng: np.random.Generator, trials: int) -> np.ndarray:
        self._side(side)
        _check_trials(trials)
        return self.displacement(points)[None]


@dataclass(frozen=True)
class Drift(_Term):
    """Linear drift in time: displacement = rate_mm_per_s·(t − t0_s) (mm; rate mm/s, t s). Either side."""

    rate_mm_per_s: tuple[float, float, float]
    t0_s: float = 0.0
    kind: ClassVar[str] = "drift"
    random: ClassVar[bool] = False

    def __post_init__(self):
        _set(self, "rate_mm_per_s", _vector("rate_mm_per_s", self.rate_mm_per_s, 3, unit="mm/s"))
        _set(self, "t0_s", _number("t0_s", self.t0_s, unit="s", limit=1e11))  # a file's times may be UNIX times

    def sample(self, points: PointSet, side: str, rng: np.random.Generator, trials: int) -> np.ndarray:
        self._side(side)
        _check_trials(trials)
        return (np.asarray(self.rate_mm_per_s) * (points.time - self.t0_s)[:, None])[None]


@dataclass(frozen=True)
class WarmUp(_Term):
    """Thermal warm-up: δ(t) = amplitude_mm·(1 − exp(−t/tau_s)) (mm; t and tau in s), docs/theory.md §5.1.
    Either side."""

    amplitude_mm: tuple[float, float, float]
    tau_s: float
    kind: ClassVar[str] = "warm_up"
    random: ClassVar[bool] = False

    def __post_init__(self):
        _set(self, "amplitude_mm", _vector("amplitude_mm", self.amplitude_mm, 3, unit="mm"))
        _set(self, "tau_s", _number("tau_s", self.tau_s, positive=True, unit="s"))

    def sample(self, points: PointSet, side: str, rng: np.random.Generator, trials: int) -> np.ndarray:
        self._side(side)
        _check_trials(trials)
        return (np.asarray(self.amplitude_mm) * (1.0 - np.exp(-points.time / self.tau_s))[:, None])[None]


# --- tables ------------------------------------------------------------------------------------------------
def _term_fields(cls) -> list[dataclasses.Field]:
    return [f for f in dataclasses.fields(cls) if f.init]  # the options, not what __post_init__ derives


def _term_from_dict(entry, loc: str, side: str) -> ErrorTerm:
    if not isinstance(entry, dict):
        raise InputError(f"{loc} must be a table with a 'type' key, got {entry!r}")
    valid_types = ", ".join(TERM_TYPES)
    if "type" not in entry:
        raise InputError(f"{loc}: missing key 'type'; valid types: {valid_types}")
    kind = entry["type"]
    if not isinstance(kind, str) or kind not in TERM_TYPES:
        raise InputError(f"{loc}: unknown type {kind!r}; valid types: {valid_types}")
    cls = TERM_TYPES[kind]
    loc = f"{loc} ({kind})"
    if side not in cls.sides:
        other = cls.sides[0]
        raise InputError(
            f"{loc}: {kind} is a {other}-side term and cannot act on the {side} side; move it to the {other} list"
        )
    fields = _term_fields(cls)
    names = [f.name for f in fields]
    for key in entry:
        if key != "type" and key not in names:
            raise InputError(f"{loc}: unknown key {key!r}; valid keys: {', '.join(names)}")
    required = [f.name for f in fields if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING]
    for name in required:
        if name not in entry:
            raise InputError(f"{loc}: missing key {name!r}; required keys: {', '.join(required)}")
    try:
        term: Any = cls(**{k: v for k, v in entry.items() if k != "type"})  # a concrete term (`_Term` subclass)
        return term
    except InputError as e:
        raise InputError(f"{loc}: {e}") from None
    except (TypeError, ValueError) as e:  # defensive: a value the validators did not anticipate
        raise InputError(f"{loc}: invalid value ({e})") from None


def error_model_from_dict(d: dict, where: str = "error_model") -> ErrorModel:
    """An ErrorModel from a TOML-like table:

        {"robot": [{"type": "kinematic", "seed": 3}, ...], "sensor": [{"type": "isotropic_noise", "sigma_mm": 0.02}]}

    `type` is a term's kind (see TERM_TYPES); the other keys are the term's field names (units in the names;
    tuples as lists; Affine.matrix as 3 rows; Kinematic.dh as "UR5" or a table with any of a, d, alpha,
    theta_offset, tool_mm, the rest taken from UR5).
    Every problem raises InputError naming the place, e.g. "error_model.sensor[1] (anisotropic_noise): ...".
    """
    if not isinstance(d, dict):
        raise InputError(f"{where} must be a table with keys 'robot' and/or 'sensor', got {d!r}")
    for key in d:
        if key not in SIDES:
            raise InputError(f"{where}: unknown key {key!r}; valid keys: robot, sensor")
    sides = {}
    for side in SIDES:
        entries = d.get(side, [])
        if isinstance(entries, dict):
            entries = [entries]
        if not isinstance(entries, (list, tuple)):
            raise InputError(f"{where}.{side} must be a list of tables (one per error term), got {entries!r}")
        sides[side] = tuple(_term_from_dict(e, f"{where}.{side}[{i}]", side) for i, e in enumerate(entries))
    return ErrorModel(**sides)


def _plain(value) -> Any:
    if isinstance(value, DHParameters):
        return _dh_table(value)
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    return value


def error_model_to_dict(model: ErrorModel) -> dict:
    """The table form of `model` (inverse of `error_model_from_dict`), for reports and config files."""
    out = {}
    for side in SIDES:
        out[side] = [
            {"type": t.kind, **{f.name: _plain(getattr(t, f.name)) for f in _term_fields(type(t))}}
            for t in model.terms(side)
        ]
    return out


# the terms of a field known at points, registered in TERM_TYPES after the ones above (the order messages list)
from rrbc_core.models.armterms import ArmErrors  # noqa: E402, F401
from rrbc_core.models.fieldterms import FieldUncertainty, LinearUncertainty, SampledField  # noqa: E402, F401
