"""The detection-power study of `rrbc diagnose` behind docs/diagnosis_power.md (`scripts/diagnosis_power.py` writes
the report): each effect planted at graded sizes on a planar and a volumetric layout, seeded per data set, and
whether `diagnose` names it; shared by the tests, which rerun points of it on other seeds."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from rrbc_core.analysis.diagnosis import diagnose
from rrbc_core.io.measurements import MeasurementSet
from rrbc_core.models.errormodels import PointSet
from rrbc_core.models.errorterms import Affine, AnisotropicNoise, Drift, Scale, SmoothField
from rrbc_core.registration.strategies import least_squares

SIGMA = 0.02  # mm per axis


ALPHA = 0.01


BASE_SEED = 20_260_601


EFFECTS = ("scale", "affine", "drift", "outliers", "anisotropic_noise", "smooth_field")


GEOMETRIES = ("planar 6x6", "volumetric 4x3x3")


SIZES = {
    "scale": (0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0),
    "affine": (0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0),
    "drift": (0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0),
    "smooth_field": (0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0),
    "outliers": (2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0),
    "anisotropic_noise": (1.25, 1.5, 2.0, 2.5, 3.0, 4.0),
}


X_LABEL = {
    "outliers": "outlier displacement / sigma",
    "anisotropic_noise": "noise ratio along / across line of sight",
}


FIELD_LENGTH_MM = 250.0  # smooth-field correlation length (half the 500 mm extent)


# extra panels (section "Point count and measurement order"): (effect, geometries, order); seed effect index 10+
SCANS = (
    ("smooth_field", ("planar 3x4", "planar 6x6", "planar 10x10"), "random"),
    ("smooth_field", ("volumetric 3x2x2", "volumetric 4x3x3", "volumetric 5x5x4"), "random"),
    ("drift", ("planar 6x6", "volumetric 4x3x3"), "raster"),
)


def geometry(name: str) -> np.ndarray:
    """True robot points (mm): a grid on a 500 x 500 mm plate at z = 300 ("planar AxB") or in a 500 x 500 x 400 mm
    block ("volumetric AxBxC"); the grid size is read from the name (the main panels: 6x6 and 4x3x3, 36 points)."""
    dims = [int(v) for v in name.split()[1].split("x")]
    g: tuple
    if name.startswith("planar"):
        g = np.meshgrid(np.linspace(0, 500, dims[0]), np.linspace(0, 500, dims[1]), [0.0], indexing="ij")
    else:
        g = np.meshgrid(*(np.linspace(0, e, k) for e, k in zip((500, 500, 400), dims)), indexing="ij")
    return np.column_stack([a.ravel() for a in g]) + np.array([250.0, -250.0, 300.0])


def trial_seed(effect: int, geom: int, size: int, trial: int) -> int:
    return BASE_SEED + 1_000_000 * effect + 100_000 * geom + 1_000 * size + trial


def _nonrigid_rms(robot: np.ndarray, disp: np.ndarray) -> float:
    res = least_squares(robot, robot + disp).residuals
    return float(np.sqrt(np.mean(np.sum(res**2, axis=1))))


def make_set(effect: str, geom: str, size: float, seed: int, order: str = "random"):
    """A measurement set with `effect` planted at `size` (see the module docstring; effect None = clean data);
    order "random" or "raster" (grid order, the last grid axis fastest). Returns (mset, outlier_id or None)."""
    rng = np.random.default_rng(seed)
    robot = geometry(geom)
    n = len(robot)
    rot = Rotation.random(random_state=rng).as_matrix()
    sensor = robot @ rot
    sensor = sensor - sensor.mean(axis=0) + np.array([0.0, 0.0, 2000.0])  # the sensor looks along +z
    perm = rng.permutation(n)  # drawn in both orders: the same seed gives the same rest of the data set
    t = (perm if order == "random" else np.arange(n)).astype(float) * 10.0  # 10 s per point
    ps = PointSet(robot=robot, sensor=sensor, time=t)
    disp = np.zeros((n, 3))
    outlier = None
    if effect in ("scale", "affine", "drift", "smooth_field"):
        term: Scale | Affine | Drift | SmoothField
        if effect == "scale":
            term = Scale(float(rng.choice([-1.0, 1.0])) * 1000.0, center_mm=tuple(rng.uniform(-99, 99, 3)))
        elif effect == "affine":
            a = rng.normal(size=(3, 3))
            if geom.startswith("planar"):
                a[2, :] = a[:, 2] = 0.0  # in-plane terms only (the others are invisible on a plate)
            a = 0.5 * (a + a.T)
            k = 2 if geom.startswith("planar") else 3
            a -= np.trace(a) / k * np.diag([1.0, 1.0, 1.0 if k == 3 else 0.0])  # non-uniform: beyond a scale
            term = Affine(tuple(map(tuple, a * 1e-3)))
        elif effect == "drift":
            v = rng.normal(size=3)
            term = Drift(tuple(v / np.linalg.norm(v) * 1e-3))
        else:
            term = SmoothField(rms_mm=1.0, length_mm=FIELD_LENGTH_MM, seed=int(rng.integers(2**31)))
        unit = term.sample(ps, "robot", rng, 1)[0]
        disp = unit * (size * SIGMA / _nonrigid_rms(robot, unit))
    if effect == "anisotropic_noise":
        e = AnisotropicNoise(SIGMA, size * SIGMA).sample(ps, "sensor", rng, 1)[0]
    else:
        e = rng.normal(0.0, SIGMA, (n, 3))
    if effect == "outliers":
        i = int(rng.integers(n))
        v = rng.normal(size=3)
        disp[i] = v / np.linalg.norm(v) * size * SIGMA
        outlier = f"P{i}"
    m = MeasurementSet(tuple(f"P{i}" for i in range(n)), ("both",) * n, sensor + e, robot + disp, t, (0,) * n)
    return m, outlier


def run_one(job):
    """(effect or None, geometry, size, seed[, order]) -> (names, outlier ids found, planted outlier id)."""
    effect, geom, size, seed = job[:4]
    m, outlier = make_set(effect, geom, size, seed, *job[4:])
    dg = diagnose(m, alpha=ALPHA)
    ids = []
    for e in dg.effects:
        if e.name == "outliers":
            ids = list(e.parameters["ids"])
    return dg.names, ids, outlier


def _hit(effect, names, ids, outlier, first: bool) -> bool:
    if effect not in names or (first and names[0] != effect):
        return False
    return effect != "outliers" or outlier is None or outlier in ids
