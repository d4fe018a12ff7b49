"""The compliance study behind docs/compliance_study.md (`scripts/compliance_study.py`): what the rigid model gets
wrong on a long arm that bends under its own weight, the cause named, and the gain of each model term measured by
cross-validation — on simulated data from our lift-column arm (rrbc_core/data/robots/lift_arm.urdf, with link
masses), one arm for every data set.

The arm: geometric errors (`simulation.arm_data.random_errors`, size 1: joint offsets 0.05°, origins 0.2 mm) and
joint compliances in the range measured on real shoulder joints (`PLANT`), gravity along −z. Each data set is one
file of `STATIONS` stationings (the instrument moved between them; a `group` column), 4 registration points,
10 fiducials and 10 checks per station, noise `NOISE_MM` per axis on both readings, and a weak sensor field
(`FIELD_MM`): a file as a user measures it. For every data set:

- `rrbc diagnose --urdf lift_arm`: the effects named, in how many of the stations (each diagnosed on its own);
- `rrbc calibrate --urdf lift_arm`: RMS over the checks of rigid, RRBC, VEC (geometric) and VEC + RRBC;
- `rrbc calibrate --urdf lift_arm --compliance`: the same with the load terms that cross-validation lets in, their
  identified values against the planted ones, and VEC's cross-validated RMS over the fiducials with all terms and
  with each term left out (the gain of each term);
- "calibrate once": the arm saved from the first data set (`--save-model`) and reused (`--model`) on the others,
  measured again at new stations with 8 registration points each and nothing else.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from rrbc_core.analysis.diagnosis_stations import StationsDiagnosis, diagnose_stations
from rrbc_core.analysis.saved_model import load_model
from rrbc_core.analysis.vec_compare import compare
from rrbc_core.models.urdf import load_urdf
from rrbc_core.simulation.arm_data import chain_measurements

ROBOT = "lift_arm"
PLANT = {"lift_joint.bending": 6e-6, "upper_arm_joint.compliance": 3.5e-5, "forearm_joint.compliance": 2.5e-5}
ARM_SEED = 17
STATIONS = 4
NOISE_MM = 0.05
FIELD_MM = 0.1
SEEDS = (101, 102, 103, 104, 105)


def data_set(seed: int, registration_only: bool = False):
    """One file of the study's arm (module docstring); `registration_only`: 8 registration points per station and
    the checks, no fiducials (a station as it is measured after calibrating once)."""
    n_reg, n_fid = (8 * STATIONS, 0) if registration_only else (4 * STATIONS, 10 * STATIONS)
    return chain_measurements(
        load_urdf(ROBOT), seed, kin_size=1.0, field_mm=FIELD_MM, noise_mm=NOISE_MM, n_reg=n_reg, n_fid=n_fid,
        n_chk=10 * STATIONS, n_tgt=0, stations=STATIONS, compliance=PLANT, arm_seed=ARM_SEED,
    )  # fmt: skip


def run(seeds=SEEDS, progress=None) -> dict:
    """Every data set's figures (module docstring), and the calibrate-once rows."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        saved = Path(tmp) / "arm.json"
        for k, seed in enumerate(seeds):
            mset = data_set(seed)
            geo = compare(mset, urdf=ROBOT)
            comp = compare(mset, urdf=ROBOT, compliance=True, save_model=str(saved) if k == 0 else None)
            diag = diagnose_stations(mset, urdf=ROBOT, seed=0)
            assert isinstance(diag, StationsDiagnosis)  # the file has a group column
            effects = {name: len(where) for name, where in diag.effects().items()}
            row = {
                "seed": seed,
                "effects": effects,
                "rigid": geo["rmst_mm"]["rigid"],
                "rrbc": geo["rmst_mm"]["rrbc"],
                "vec": geo["rmst_mm"]["vec"],
                "vec_rrbc": geo["rmst_mm"]["vec_rrbc"],
                "vec_compliance": comp["rmst_mm"]["vec"],
                "vec_compliance_rrbc": comp["rmst_mm"]["vec_rrbc"],
                "recommended": comp["recommended"],
                "entered": comp["compliance"]["entered"],
                "cv": comp["compliance"]["cv_rmst_mm"],
                "values": {p["name"]: (p["error"], p["std_error"]) for p in comp["parameters"] if p.get("kind")},
            }
            if k > 0:
                reuse = compare(data_set(seed + 1000, registration_only=True), model=load_model(saved))
                row["once_rigid"] = reuse["rmst_mm"]["rigid"]
                row["once_vec"] = reuse["rmst_mm"]["vec"]
            rows.append(row)
            if progress:
                progress(k + 1)
    return {"rows": rows, "plant": PLANT}


__all__ = ["PLANT", "SEEDS", "data_set", "run"]
