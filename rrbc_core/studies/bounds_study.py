"""Do the per-point bounds hold? Coverage of held-out checks by their `bound95_mm` on seeded simulations and on the
public measured data rrbc reads (scripts/uncertainty_study.py writes docs/uncertainty.md from `run`).

For each data set and method (rigid, and RRBC with idw, tps and auto): how many checks got a bound (the rest are
withheld with a warning), the share of those within their bound (the aim: 90-99 %), the median bound against the
checks' 95th-percentile error (sharp: at most 2), and that share's binomial standard error. Every check is scored
against the robot's own reading of it, as `rrbc correct` scores it; each station is corrected on its own.

Data sets:

* seeded simulations, not the bounds' model: `simulation.field_data` (a smooth field of plane waves in a volume or
  off coplanar fiducials; a tracker-shaped noise; repeats; 100 fiducials; a short wavelength) and
  `simulation.station_data` (real-like stations of a lift-column robot, half the evaluation points as fiducials);
* NIST's CRPI breadboard (`rrbc_core/data/nist_crpi_registration_data1.csv`, 10 sites read 10 times): leave one
  site out, the other nine are registration points and fiducials, the left-out site is the check (10 files, 10
  checks: few, reported as they are);
* the Hilti construction-robot stationing data (public, CC BY-NC-SA 3.0, not shipped; `--data` a clone): each
  station with the board's 8 points as fiducials (`stationing`) and with every other evaluation point a fiducial too
  (`half`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rrbc_core.correction.pipeline import CorrectionResult, correct_measurements
from rrbc_core.correction.stations import StationsResult, correct_stations
from rrbc_core.io.measurements import MeasurementSet
from rrbc_core.methods import MethodOptions

METHODS = ("none", "idw", "tps", "auto")
SEEDS = 10
FIELD_SHAPES: dict[str, dict] = {
    "field, volume": {},
    "field, coplanar fiducials, checks off the plane": {"layout": "plane"},
    "field, tracker-shaped noise 0.08 mm": {"polar": True, "noise_mm": 0.08},
    "field, every point read twice": {"repeats": True},
    "field, 100 fiducials": {"n_fiducials": 100, "n_checks": 100},
    "field, 2 mm at 500 mm wavelength": {"bias_mm": 2.0, "wavelength_mm": 500.0},
}


def _pairs(res: CorrectionResult | StationsResult) -> tuple[np.ndarray, np.ndarray]:
    """(errors, bounds) of the RRBC position at every check (NaN bound: withheld)."""
    parts = res.stations if isinstance(res, StationsResult) else (res,)
    e = np.concatenate([r.error_rrbc for r in parts])
    b = np.concatenate([r.bounds.checks.bound95_mm if r.bounds.checks is not None else np.zeros(0) for r in parts])
    return e, b


def score(e: np.ndarray, b: np.ndarray) -> dict:
    """Coverage of errors e (N,) by bounds b (N,; NaN withheld): checks, bounded, within, share, its binomial
    standard error, the median bound, the bounded checks' 95th-percentile error and their ratio."""
    ok = np.isfinite(b)
    n = int(ok.sum())
    if n == 0:
        return {"checks": int(len(e)), "bounded": 0}
    share = float(np.mean(e[ok] <= b[ok]))
    p95 = float(np.percentile(e[ok], 95))
    med = float(np.median(b[ok]))
    return {
        "checks": int(len(e)),
        "bounded": n,
        "within": int(np.sum(e[ok] <= b[ok])),
        "share": share,
        "se": float(np.sqrt(max(share * (1 - share), 0.05 * 0.95) / n)),
        "median_bound_mm": med,
        "p95_error_mm": p95,
        "sharpness": med / p95 if p95 > 0 else None,
    }


def _collect(msets, method: str, stations: bool = False) -> dict:
    es, bs = [], []
    for m in msets:
        opts = MethodOptions.named("least-squares", method)
        res = correct_stations(m, opts) if stations else correct_measurements(m, opts)
        e, b = _pairs(res)
        es.append(e)
        bs.append(b)
    return score(np.concatenate(es), np.concatenate(bs))


def simulated(seeds: int = SEEDS) -> list[dict]:
    """Rows for the seeded simulations."""
    from rrbc_core.simulation.field_data import field_measurements
    from rrbc_core.simulation.station_data import drawn_stations

    rows = []
    for name, shape in FIELD_SHAPES.items():
        msets = [field_measurements(1000 + s, **shape) for s in range(seeds)]
        rows += [{"data": name, "method": m, **_collect(msets, m)} for m in METHODS]
    stations = [drawn_stations(2000 + s, s) for s in range(seeds)]
    rows += [{"data": "real-like stations", "method": m, **_collect(stations, m, True)} for m in METHODS]
    return rows


def crpi_files() -> list[MeasurementSet]:
    """NIST CRPI's ten sites, one file per left-out site (module docstring)."""
    from rrbc_core.studies import crpi

    sites = crpi.load()
    out = []
    for k in range(len(sites.truth)):
        ids, roles, sensor, robot = [], [], [], []
        for j, (truth, reads) in enumerate(zip(sites.truth, sites.readings)):
            for r in reads:
                ids.append(f"S{j + 1}")
                roles.append("check" if j == k else "both")
                sensor.append(truth)
                robot.append(r)
        n = len(ids)
        out.append(
            MeasurementSet(
                tuple(ids),
                tuple(roles),
                np.array(sensor),
                np.array(robot),
                np.full(n, np.nan),
                tuple(range(2, n + 2)),
                f"crpi without S{k + 1}",
            )
        )
    return out


def measured(data: str | Path | None = None) -> list[dict]:
    """Rows for the measured data: CRPI always; the Hilti stationing data when `data` is a clone of it."""
    rows = []
    files = crpi_files()
    rows += [{"data": "NIST CRPI breadboard, leave one site out", "method": m, **_collect(files, m)} for m in METHODS]
    if data is not None:
        from rrbc_core.io.stationing_yaml import read_stationing_yaml
        from rrbc_core.models.urdf import load_urdf
        from rrbc_core.studies.stationing_study import DATA_SETS, TIP, paths

        urdf, paths_of = paths(data)
        chain = load_urdf(urdf, tip=TIP)
        for name in DATA_SETS:
            for fid in ("half", "stationing"):
                m = read_stationing_yaml(paths_of[name], chain, fid)
                rows += [
                    {"data": f"Hilti {name}, fiducials: {fid}", "method": mt, **_collect([m], mt, True)}
                    for mt in METHODS
                ]
    return rows


def run(data: str | Path | None = None, seeds: int = SEEDS) -> dict:
    """Every row (module docstring)."""
    return {"simulated": simulated(seeds), "measured": measured(data), "methods": METHODS}
