"""When does RRBC win, when does model-based calibration (VEC), and when both: simulated cells with joint angles
(`joint_measurements`), compared by `analysis.vec_compare.compare` (what `rrbc calibrate` runs). The study script
is scripts/vec_study.py; its report docs/vec_study.md.

Physics (robot base frame, mm): a UR5 (tool 100 mm) commanded to joints q puts its tool at p = FK(true DH, q);
the robot reports b = FK(nominal DH, q) plus repeatability noise; the sensor reads s = T⁻¹(p) + field(p) + noise.
DH errors: `perturbed` with (0.1°, 0.2 mm, 0.05°) × dh_size; the field: a smooth random field (`SmoothField`,
300 mm correlation length) of `field_mm` RMS; poses: joints uniform within ±0.7 rad of the tool-down seed.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from rrbc_core.io.measurements import MeasurementSet
from rrbc_core.models.kinematics import UR5, UR5_TOOL_DOWN_SEED, forward, perturbed

TOOL_MM = 100.0


def _field(term, s: np.ndarray) -> np.ndarray:
    from rrbc_core.models.errormodels import PointSet

    pts = PointSet(robot=s, sensor=s, time=np.zeros(len(s)), tool_rotation=None, joint_seed=None)
    return term.sample(pts, "sensor", None, 1)[0]


def joint_measurements(
    seed: int,
    dh_size: float = 1.0,
    field_mm: float = 0.0,
    noise_mm: float = 0.02,
    n_reg: int = 8,
    n_fid: int = 30,
    n_chk: int = 30,
    n_tgt: int = 3,
    source: str = "<simulated>",
    point_shift_rad=None,
    family_shift_rad=None,
) -> MeasurementSet:
    """A simulated measurement set with joint angles q1..q6 (degrees) in its extra columns (module docstring).
    `point_shift_rad` (6,): added to the checks' and targets' joint values (reached in other configurations than
    the fiducials). `family_shift_rad` (6,): added to every other row's joint values (registration, fiducials,
    checks and targets alike: two configuration families throughout, e.g. the wrist turned)."""
    from rrbc_core.models.errorterms import SmoothField

    rng = np.random.default_rng(seed)
    nominal = UR5.with_tool(TOOL_MM)
    true = perturbed(nominal, rng, 0.1 * dh_size, 0.2 * dh_size, 0.05 * dh_size)
    rot = Rotation.from_rotvec(rng.normal(size=3) * 0.3).as_matrix()  # sensor -> robot
    t = np.array([1100.0, -450.0, 1250.0])
    n = n_reg + n_fid + n_chk + n_tgt
    q = UR5_TOOL_DOWN_SEED + rng.uniform(-0.7, 0.7, (n, 6))
    if point_shift_rad is not None:
        q[n_reg + n_fid :] += np.asarray(point_shift_rad, float)
    if family_shift_rad is not None:
        q[1::2] += np.asarray(family_shift_rad, float)
    p, _ = forward(true, q)
    b_nom, _ = forward(nominal, q)
    s = (p - t) @ rot
    if field_mm > 0:
        s = s + _field(SmoothField(rms_mm=field_mm, length_mm=300.0, seed=seed), s)
    s = s + rng.normal(0, noise_mm, s.shape)
    b = b_nom + rng.normal(0, noise_mm, b_nom.shape)
    roles = ["registration"] * n_reg + ["fiducial"] * n_fid + ["check"] * n_chk + ["target"] * n_tgt
    ids = [f"{r[0].upper()}{i + 1}" for i, r in enumerate(roles)]
    b[n - n_tgt :] = np.nan
    return MeasurementSet(
        ids=tuple(ids),
        roles=tuple(roles),
        sensor=s,
        robot=b,
        time=np.full(n, np.nan),
        lines=tuple(0 for _ in ids),
        source=source,
        extra={f"q{j + 1}": tuple(repr(float(v)) for v in np.degrees(q[:, j])) for j in range(6)},
    )


SCENARIOS = {
    "kinematic": {"dh_size": 1.0, "field_mm": 0.0},
    "sensor field": {"dh_size": 0.0, "field_mm": 0.3},
    "both": {"dh_size": 1.0, "field_mm": 0.3},
}
FIDUCIALS = (10, 20, 40)
NOISES = (0.01, 0.05)
SEEDS = (1, 2, 3)


def _cell_row(task: tuple) -> dict:
    """One cell of the study (a task of `run`): its four methods' RMST, the recommendation, the kinematic claim."""
    from rrbc_core.analysis.vec_compare import compare

    name, kw, nf, noise, seed = task
    m = joint_measurements(seed, noise_mm=noise, n_fid=nf, **kw)
    out = compare(m, "ur5", TOOL_MM)
    best = min(out["rmst_mm"], key=out["rmst_mm"].get)
    return {
        "scenario": name,
        "fiducials": nf,
        "noise_mm": noise,
        "seed": seed,
        **{f"rmst_{k}": v for k, v in out["rmst_mm"].items()},
        "best": best,
        "recommended": out["recommended"],
        "kinematic_claimed": out["kinematic_error"]["claimed"],
    }


def run(
    scenarios=SCENARIOS, fiducials=FIDUCIALS, noises=NOISES, seeds=SEEDS, progress=None, scheduler: str | None = None
) -> list[dict]:
    """One row per (scenario, fiducials, noise, seed): the four methods' RMST over 30 checks, the recommendation
    (made without the checks), whether a kinematic error was claimed. Each cell is seeded by its own seed and is
    one task of `runtime.tasks.run_tasks` (`scheduler`: in this process by default, "local" or a dask address);
    rows come back in this order wherever they ran."""
    from rrbc_core.runtime.tasks import run_tasks

    tasks = [
        (name, kw, nf, noise, seed)
        for name, kw in scenarios.items()
        for nf in fiducials
        for noise in noises
        for seed in seeds
    ]
    done = [0]

    def tick(n):
        done[0] += n
        progress(done[0])

    return run_tasks(_cell_row, tasks, scheduler, progress=tick if progress else None)


MIXED_SEEDS = tuple(range(20, 32))
KIND_NAMES = ("kinematic", "sensor field", "both")


def mixed_case(seed: int) -> tuple[str, dict]:
    """The seeded mixed case `seed`: (kind, joint_measurements keywords): kind = seed % 3 (kinematic errors only,
    a sensor field only, both), sizes drawn from the seed (DH ×0.5–2, field 0.1–0.5 mm RMS)."""
    rng = np.random.default_rng(seed)
    kind = seed % 3
    kw = {
        0: {"dh_size": rng.uniform(0.5, 2)},
        1: {"dh_size": 0.0, "field_mm": rng.uniform(0.1, 0.5)},
        2: {"dh_size": rng.uniform(0.5, 2), "field_mm": rng.uniform(0.1, 0.5)},
    }[kind]
    return KIND_NAMES[kind], kw


def mixed_cases(seeds=MIXED_SEEDS) -> list[dict]:
    """Per seeded mixed case: its kind, the best method on the checks, the recommendation, the kinematic verdict
    (claimed; the identified errors' χ² p-value; rrbc diagnose's test p-values, alone and beside a field) and the ratio of VEC's best cross-validated RMST to RRBC's."""
    from rrbc_core.analysis.vec_compare import compare

    out = []
    for seed in seeds:
        kind, kw = mixed_case(seed)
        r = compare(joint_measurements(seed, **kw), "ur5", TOOL_MM)
        cv = r["cv_rmst_mm"]
        out.append(
            {
                "seed": seed,
                "kind": kind,
                "best": min(r["rmst_mm"], key=r["rmst_mm"].get),
                "recommended": r["recommended"],
                "claimed": r["kinematic_error"]["claimed"],
                "p_value": r["kinematic_error"]["p_value"],
                "test_p": r["kinematic_error"]["verdict"]["tests"].get("kinematic"),
                "field_p": r["kinematic_error"]["verdict"]["tests"].get("kinematic_beside_field"),
                "cv_ratio": min(cv["vec"], cv["vec_rrbc"]) / cv["rrbc"],
                "rmst_vec": r["rmst_mm"]["vec"],
            }
        )
    return out
