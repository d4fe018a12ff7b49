"""The real-data study behind docs/real_data.md (`scripts/stationing_study.py`): rrbc on public measured data no
one here wrote — the construction-robot stationing data sets (a lift-column arm carrying a prism, measured by a
total station at about 450 waypoints per data set; `io.stationing_yaml`), read from a copy the user fetches
(they are not redistributed with rrbc: docs/real_data.md says where they are and under which licence).

For every data set (one YAML file; one station per column height and solution space):

- **as a site runs it**: the stationing points are the registration points and the only fiducials, the evaluation
  points the checks: rigid against RRBC (IDW, tps, auto), per station, pooled over the file;
- **fiducials around the checks**: every other evaluation point of a station a fiducial too, the rest checks, then
  the halves swapped; the check errors of both halves pooled (every evaluation point scored once);
- **the arm's model** (`rrbc calibrate --urdf`), on the same two halves: geometric VEC, VEC with the load terms
  (`--compliance`), and the combination with RRBC, the recommendation made without the checks;
- **pooled stations**: the stations' rows put in one station (the `group` column dropped), as a user who does not
  split the file gets them: the largest correction against the largest fiducial correction, and the warnings;
- **calibrate once**: the arm identified with its load terms on the first data set (both halves) and reused on every
  other data set, registering each station on its stationing points alone.

Units mm. The robot columns are the URDF's nominal forward kinematics of the joint states (`io.stationing_yaml`).
"""

from __future__ import annotations

import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from rrbc_core.analysis.saved_model import load_model
from rrbc_core.analysis.vec_compare import compare
from rrbc_core.correction.pipeline import CorrectionResult
from rrbc_core.correction.stations import StationsResult, correct_stations
from rrbc_core.io.groups import GROUP_COLUMN, group_names
from rrbc_core.io.measurements import MeasurementSet
from rrbc_core.io.stationing_yaml import read_stationing_yaml
from rrbc_core.methods import MethodOptions
from rrbc_core.models.urdf import load_urdf

#: the data sets in the order of the public repository's README (the first is the one it calls "used for calibration")
DATA_SETS = ("flat", "pallet", "orthogonal_wood", "wood_left_track", "seesaw", "diagonal_wood", "outdoor")
TIP = "prism"
RRBC_METHODS = ("idw", "tps", "auto")


def paths(root: str | Path) -> tuple[Path, dict[str, Path]]:
    """The URDF and the data files of a copy of the public repository at `root` (its data/ folder)."""
    root = Path(root)
    return root / "data" / "trailblazer.urdf", {n: root / "data" / "datasets" / f"{n}.yaml" for n in DATA_SETS}


def _errors(res: StationsResult) -> tuple[np.ndarray, np.ndarray]:
    """(rigid, RRBC) check error vectors (C, 3), robot frame, mm, over all stations."""
    rig, rr = [], []
    for r in res.stations:
        if r.checks_corrected is None:
            continue
        rig.append(r.checks_corrected.robot_rigid - r.checks.robot)
        rr.append(r.checks_corrected.robot_rrbc - r.checks.robot)
    return np.vstack(rig), np.vstack(rr)


def stats(e: np.ndarray) -> dict:
    """RMS of the 3-D errors and the 95th percentile of the horizontal (xy) errors, mm, of error vectors (C, 3)."""
    return {
        "rms": float(np.sqrt(np.mean(np.sum(e**2, axis=1)))),
        "p95_xy": float(np.percentile(np.linalg.norm(e[:, :2], axis=1), 95)),
        "n": int(len(e)),
    }


def _rrbc(msets: list[MeasurementSet]) -> dict:
    """Rigid and each RRBC method over the checks of all `msets` pooled, and the stations RRBC made worse."""
    out: dict = {}
    for m in RRBC_METHODS:
        rig, rr, worse, n_st = [], [], 0, 0
        for mset in msets:
            res = correct_stations(mset, MethodOptions(interpolation=m))
            assert isinstance(res, StationsResult)
            a, b = _errors(res)
            rig.append(a)
            rr.append(b)
            for r in res.stations:
                n_st += 1
                worse += int(np.sqrt(np.mean(r.error_rrbc**2)) > np.sqrt(np.mean(r.error_rigid**2)))
        out["rigid"] = stats(np.vstack(rig))
        out[m] = {**stats(np.vstack(rr)), "stations_worse": worse, "stations": n_st}
    return out


def _pooled(mset: MeasurementSet) -> MeasurementSet:
    """The file as one station: the `group` column dropped, ids made unique by their station."""
    g = mset.extra[GROUP_COLUMN]
    extra = {k: v for k, v in mset.extra.items() if k != GROUP_COLUMN}
    return replace(mset, ids=tuple(f"{gg}/{i}" for gg, i in zip(g, mset.ids)), extra=extra)


def _blow_up(mset: MeasurementSet) -> dict:
    """tps and linear on the pooled stations: check RMS rigid and RRBC, the largest check correction against the
    largest fiducial correction, and how many warnings rrbc gives."""
    pooled = _pooled(mset)
    out = {}
    for m in ("tps", "linear"):
        res = correct_stations(pooled, MethodOptions(interpolation=m))
        assert isinstance(res, CorrectionResult) and res.checks_corrected is not None
        fid = float(np.max(np.linalg.norm(res.fiducial_corrections, axis=1)))
        chk = float(np.max(np.linalg.norm(res.checks_corrected.correction, axis=1)))
        out[m] = {
            "rigid": float(np.sqrt(np.mean(res.error_rigid**2))),
            "rrbc": float(np.sqrt(np.mean(res.error_rrbc**2))),
            "max_fiducial_correction": fid,
            "max_check_correction": chk,
            "warnings": len(res.warnings()),
        }
    return out


def _calibration(halves: list[MeasurementSet], urdf: Path, save: str | None = None) -> dict:
    """`rrbc calibrate` geometric and with load terms on each half; RMS over both halves' checks pooled."""
    geo = [compare(h, urdf=str(urdf), tip=TIP) for h in halves]
    comp = [
        compare(h, urdf=str(urdf), tip=TIP, compliance=True, save_model=save if k == 0 else None)
        for k, h in enumerate(halves)
    ]

    def pool(results, method):
        n = np.array([r["checks"] for r in results], float)
        v = np.array([r["rmst_mm"][method] for r in results], float)
        return float(np.sqrt(np.sum(n * v**2) / np.sum(n)))

    return {
        "rigid": pool(geo, "rigid"),
        "rrbc": pool(geo, "rrbc"),
        "vec": pool(geo, "vec"),
        "vec_rrbc": pool(geo, "vec_rrbc"),
        "vec_compliance": pool(comp, "vec"),
        "vec_compliance_rrbc": pool(comp, "vec_rrbc"),
        "recommended": [r["recommended"] for r in comp],
        "entered": [{p["name"]: (p["error"], p["std_error"]) for p in r["parameters"] if "kind" in p} for r in comp],
        "refused": [r["compliance"]["refused"] for r in comp],
    }


def run(root: str | Path, data_sets=DATA_SETS, progress=None) -> dict:
    """Every data set's figures (module docstring)."""
    urdf, files = paths(root)
    chain = load_urdf(urdf, tip=TIP)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        saved = str(Path(tmp) / "arm.json")
        for k, name in enumerate(data_sets):
            if progress is not None:
                progress(k + 1, name)
            site = read_stationing_yaml(files[name], chain, "stationing")
            halves = [read_stationing_yaml(files[name], chain, f) for f in ("half", "half-swapped")]
            row = {
                "name": name,
                "stations": len(group_names(site)),
                "checks": sum(1 for r in site.roles if r == "check"),
                "site": _rrbc([site]),
                "halves": _rrbc(halves),
                "pooled": _blow_up(halves[0]),
                "calibration": _calibration(halves, urdf, save=saved if k == 0 else None),
            }
            if k > 0:
                once = compare(site, urdf=str(urdf), tip=TIP, model=load_model(saved))
                row["once"] = {"rigid": once["rmst_mm"]["rigid"], "vec": once["rmst_mm"]["vec"]}
            rows.append(row)
    return {"rows": rows, "calibrated_on": data_sets[0]}
