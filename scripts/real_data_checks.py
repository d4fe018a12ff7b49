"""Seeded sweeps behind issue 28's figures (real-like data: stations, interpolation chosen by the data, mixed effects).

    .venv/bin/python scripts/real_data_checks.py [auto] [stations] [mixed] [arm]

Prints one block per sweep (all by default); every case has its own seed, so the output is the same on every run.

- auto: 40 real-like single stations (`simulation.station_data`, half the evaluation points as fiducials around the
  others; bias 0-5 mm, correlation length 150-600 mm, robot noise 0.02-0.3 mm): check RMS of each fixed method and
  of `--interpolation auto`; how often auto is within 10 % of the best fixed method and how often it is more than
  5 % worse than rigid.
- stations: one 5-station file, grouped and pooled, with each interpolation: pooled vs per-station FRE and check
  RMS (what `rrbc correct` prints on the two files).
- mixed: `rrbc diagnose` on 30 cases of a smooth field (5-30 noise levels) with drift (5-20 over the run), and on
  100 cases of the field alone: how often drift is missed, anisotropic noise or outliers named, drift invented.
- arm: `rrbc diagnose` on 60 UR5 files with joint columns and kinematic errors (half with a sensor field): how often
  `outliers` is named.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from rrbc_core.analysis.diagnosis import diagnose
from rrbc_core.correction.pipeline import correct_measurements
from rrbc_core.correction.stations import correct_stations
from rrbc_core.methods import MethodOptions
from rrbc_core.simulation.station_data import station_measurements

FIXED = ("none", "idw", "linear", "tps", "gp")


def auto(n: int = 40) -> None:
    from tests.interpolation.test_auto import real_like_station

    near = worse = 0
    for seed in range(n):
        mset = real_like_station(seed)
        rmst = {}
        for m in (*FIXED, "auto"):
            res = correct_measurements(mset, MethodOptions.named("least-squares", m))
            rmst[m] = res.summary()["rmst_rrbc_mm"]
            if m == "auto":
                chosen = res.choice.method.name
        near += rmst["auto"] <= 1.10 * min(rmst[m] for m in FIXED)
        worse += rmst["auto"] > 1.05 * rmst["none"]
        print(f"  seed {seed:2d}: " + " ".join(f"{m} {v:.3f}" for m, v in rmst.items()) + f"  (auto chose {chosen})")
    print(f"auto within 10 % of the best fixed method: {near} of {n}; more than 5 % worse than rigid: {worse} of {n}")


def stations() -> None:
    for ef in (0.0, 0.5):
        for m in ("idw", "tps", "linear", "auto"):
            opts = MethodOptions.named("least-squares", m)
            grouped = correct_stations(station_measurements(1, eval_fiducials=ef), opts)
            pooled = correct_measurements(station_measurements(1, eval_fiducials=ef, group_column=False), opts)
            g, p = grouped.summary(), pooled.summary()
            fre = g["fre_rms_mm_per_station"]
            print(
                f"fiducials {'board + half the evaluation points' if ef else 'board only':35s} {m:6s}: "
                f"pooled FRE {pooled.registration.fre_rms_mm:.2f} mm, check RMS rigid {p['rmst_rigid_mm']:.2f} -> "
                f"RRBC {p['rmst_rrbc_mm']:.2f} mm ({len(pooled.warnings())} warnings); per station FRE "
                f"{fre['min']:.2f}-{fre['max']:.2f} mm, check RMS rigid {g['rmst_rigid_mm']:.2f} -> RRBC "
                f"{g['rmst_rrbc_mm']:.2f} mm"
            )


def mixed() -> None:
    from tests.analysis.test_diagnosis_mixed import large_field_case

    missed = aniso = outl = 0
    for seed in range(30):
        names = diagnose(large_field_case(seed, drift=True)).names
        missed += "drift" not in names
        aniso += "anisotropic_noise" in names
        outl += "outliers" in names
    print(f"field + drift, 30 cases: drift missed {missed}, anisotropic_noise named {aniso}, outliers named {outl}")
    invented = extra = 0
    for seed in range(100):
        names = diagnose(large_field_case(seed, drift=False)).names
        invented += "drift" in names
        extra += bool(set(names) - {"smooth_field", "affine", "scale"})
    print(f"field alone, 100 cases: drift named {invented}, any effect beyond the field's {extra}")


def arm() -> None:
    from rrbc_core.studies.vec_study import TOOL_MM, joint_measurements

    named = 0
    for seed in range(60):
        rng = np.random.default_rng(5500 + seed)
        m = joint_measurements(
            seed,
            noise_mm=float(rng.uniform(0.01, 0.05)),
            dh_size=float(rng.uniform(0.5, 5.0)),
            field_mm=0.2 if seed % 2 else 0.0,
        )
        named += "outliers" in diagnose(m, tool_mm=TOOL_MM).names
    print(f"UR5 with kinematic errors (half with a sensor field), 60 cases: outliers named {named}")


if __name__ == "__main__":
    wanted = sys.argv[1:] or ["auto", "stations", "mixed", "arm"]
    for name in wanted:
        print(f"== {name}")
        {"auto": auto, "stations": stations, "mixed": mixed, "arm": arm}[name]()
