"""Point-level measured registration data from NIST's breadboard (`rrbc reproduce crpi`, docs/reference/crpi.md).

The data (`rrbc_core/data/nist_crpi_registration_data1.csv`, copied unchanged; source: J. A. Marvel, NIST,
Collaborative Robot Programming Interface, `Applications/ML Registration Demo/data1.csv` in the public GitHub
repository jeremy-marvel/CRPI, 2019): 10 breadboard sites (frame N, the plate; z = 11 mm), 10 robot readings of
each (robot base frame, mm) with the stylus seated again every time.

What is computed here, model-free:
- the rigid fit N → robot of the ten site means (least squares: robot ≈ R·truth + t) and each site's residual
  vector r_i = mean reading − (R·truth_i + t) (robot frame, mm);
- repeatability: the pooled within-site standard deviation per robot axis (90 degrees of freedom);
- the empirical variogram of the residuals, γ(h) = ½·mean |r_i − r_j|² over site pairs in distance bins (mm²),
  each bin with a leave-one-site-out jackknife standard error;
- the leave-one-site-out experiment: for each site h, a least-squares fit on the other nine site means, RRBC from
  those nine as fiducials (corrections e_i = Rᵀ(b_i − t) − s_i, interpolated to truth_h), and the distance from
  each prediction to site h's mean reading; RMS over the ten sites, for every interpolation method.

The candidate error models and their scores are in `crpi_models`.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rrbc_core.correction.rrbc import correct_points, fiducial_corrections
from rrbc_core.errors import InputError
from rrbc_core.interpolation import make_interpolator
from rrbc_core.registration.strategies import least_squares

DATA = Path(__file__).resolve().parents[1] / "data" / "nist_crpi_registration_data1.csv"
CITATION = (
    "J. A. Marvel (NIST), Collaborative Robot Programming Interface (CRPI), "
    "Applications/ML Registration Demo/data1.csv, github.com/jeremy-marvel/CRPI (2019)"
)
COLUMNS = (
    "raw_robot_X", "raw_robot_Y", "raw_robot_Z",
    "registered_robot_X", "registered_robot_Y", "registered_robot_Z",
    "truth_X", "truth_Y", "truth_Z",
)  # fmt: skip
#: Interpolation methods of the leave-one-site-out experiment (the project's registry names) and their options.
LOSO_METHODS = {"idw": {"k": 4, "power": 2.0}, "linear": {}, "tps": {}, "gp": {}}
#: Variogram distance bins (mm): the ten sites' 45 pairs lie between 175 and ~830 mm apart.
VARIOGRAM_EDGES = (0.0, 320.0, 480.0, 640.0, 1e9)


@dataclass(frozen=True, eq=False)
class Sites:
    """The readings grouped by site: truth (S, 3) frame N and readings[i] (n_i, 3) robot frame, mm."""

    truth: np.ndarray
    readings: tuple

    @property
    def means(self) -> np.ndarray:
        """(S, 3) mean robot reading per site (robot frame, mm)."""
        return np.array([r.mean(axis=0) for r in self.readings])

    @property
    def counts(self) -> np.ndarray:
        return np.array([len(r) for r in self.readings])


def parse(text: str, source: str = "<text>") -> Sites:
    """Sites from the CSV text (header of the nine COLUMNS); rows grouped by their truth position, in order of
    first appearance. Raises InputError naming the line for a malformed file."""
    rows = list(csv.reader(io.StringIO(text)))
    if not rows or tuple(c.strip() for c in rows[0]) != COLUMNS:
        raise InputError(f"{source}: line 1: expected the header {', '.join(COLUMNS)}")
    values = []
    for k, row in enumerate(rows[1:], start=2):
        if not row:
            continue
        if len(row) != len(COLUMNS):
            raise InputError(f"{source}: line {k}: {len(row)} cells, expected {len(COLUMNS)}")
        try:
            v = [float(c) for c in row]
        except ValueError:
            raise InputError(f"{source}: line {k}: a cell is not a number") from None
        if not all(np.isfinite(v)) or max(abs(x) for x in v) > 1e6:
            raise InputError(f"{source}: line {k}: values must be finite and at most 1e6 mm")
        values.append(v)
    a = np.array(values).reshape(-1, len(COLUMNS))
    truth = a[:, 6:9] + 0.0  # -0 and 0 are one site
    keys: dict[tuple, list[int]] = {}
    for i, t in enumerate(map(tuple, truth)):
        keys.setdefault(t, []).append(i)
    if len(keys) < 5:
        raise InputError(f"{source}: {len(keys)} distinct sites; the study needs at least 5")
    order = list(keys)
    return Sites(np.array(order), tuple(a[keys[t], 0:3] for t in order))


def load(path: str | Path = DATA) -> Sites:
    p = Path(path)
    return parse(p.read_text(encoding="utf-8"), str(p))


def repeatability(sites: Sites) -> np.ndarray:
    """(3,) pooled within-site standard deviation per robot axis (mm)."""
    ss = sum(np.sum((r - r.mean(axis=0)) ** 2, axis=0) for r in sites.readings)
    dof = int(np.sum(sites.counts - 1))
    return np.sqrt(ss / dof)


def rigid_fit(truth: np.ndarray, means: np.ndarray):
    """The least-squares mapping N → robot and the residuals (S, 3), robot frame, mm."""
    mapping = least_squares(truth, means).mapping
    return mapping, means - mapping.apply(truth)


def pair_distances(truth: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    i, j = np.triu_indices(len(truth), k=1)
    return i, j, np.linalg.norm(truth[i] - truth[j], axis=1)


def semivariances(truth: np.ndarray, resid: np.ndarray, edges=VARIOGRAM_EDGES) -> np.ndarray:
    """γ per bin (B,) mm² for residuals (..., S, 3): ½ mean |r_i − r_j|² over the pairs in each bin."""
    i, j, d = pair_distances(truth)
    sq = 0.5 * np.sum((resid[..., i, :] - resid[..., j, :]) ** 2, axis=-1)
    b = np.digitize(d, edges[1:-1])
    return np.stack([sq[..., b == k].mean(axis=-1) for k in range(len(edges) - 1)], axis=-1)


@dataclass(frozen=True)
class Variogram:
    """Bins: lower and upper edge (mm), mean pair distance (mm), pairs, γ (mm²) and its jackknife standard error."""

    lo: tuple
    hi: tuple
    distance_mm: tuple
    pairs: tuple
    gamma_mm2: tuple
    se_mm2: tuple

    def to_json(self) -> dict:
        return {
            "bins": [
                {
                    "lo_mm": lo,
                    "hi_mm": hi if hi < 1e8 else None,
                    "distance_mm": d,
                    "pairs": n,
                    "gamma_mm2": g,
                    "se_mm2": s,
                }
                for lo, hi, d, n, g, s in zip(
                    self.lo, self.hi, self.distance_mm, self.pairs, self.gamma_mm2, self.se_mm2
                )
            ],
            "definition": "gamma = 1/2 mean |r_i - r_j|^2 over site pairs (rigid-fit residuals, robot frame, mm^2); "
            "se: leave-one-site-out jackknife",
        }


def variogram(truth: np.ndarray, resid: np.ndarray, edges=VARIOGRAM_EDGES) -> Variogram:
    """The empirical variogram of residuals (S, 3) at the sites, with a delete-one-site jackknife standard error
    (each site left out in turn, the pairs it is in dropped)."""
    _, _, d = pair_distances(truth)
    b = np.digitize(d, edges[1:-1])
    g = semivariances(truth, resid, edges)
    s = len(truth)
    jack = np.array([semivariances(np.delete(truth, k, 0), np.delete(resid, k, 0), edges) for k in range(s)])  # (S, B)
    se = np.sqrt((s - 1) / s * np.sum((jack - jack.mean(axis=0)) ** 2, axis=0))
    return Variogram(
        tuple(float(x) for x in edges[:-1]),
        tuple(float(x) for x in edges[1:]),
        tuple(float(d[b == k].mean()) for k in range(len(edges) - 1)),
        tuple(int(np.sum(b == k)) for k in range(len(edges) - 1)),
        tuple(float(x) for x in g),
        tuple(float(x) for x in se),
    )


def loso(truth: np.ndarray, means: np.ndarray, method: str = "idw", **options) -> tuple[np.ndarray, np.ndarray]:
    """Leave-one-site-out errors (S,) rigid and RRBC (mm): site h predicted from a least-squares fit and RRBC
    (`method`, its `options`) on the other sites' means, scored against site h's mean reading."""
    s = len(truth)
    rigid, rrbc = np.empty(s), np.empty(s)
    for h in range(s):
        o = np.arange(s) != h
        mapping = least_squares(truth[o], means[o]).mapping
        corr = fiducial_corrections(mapping, truth[o], means[o])
        fitted = make_interpolator(method, **options).fit(truth[o], corr)
        cp = correct_points(mapping, fitted, truth[h : h + 1])
        rigid[h] = np.linalg.norm(cp.robot_rigid[0] - means[h])
        rrbc[h] = np.linalg.norm(cp.robot_rrbc[0] - means[h])
    return rigid, rrbc


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))
