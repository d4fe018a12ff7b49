"""Simulated measurement files WITH joint angles (q1..q6, degrees) for the calibration tests: a UR5 with planted DH
errors and/or a smooth sensor-distortion field, seen by a sensor; rows of every role, each pose with its joints.

Physics (robot base frame, mm): the arm commanded to joints q puts its tool at p = FK(true DH, q); the robot
reports b = FK(nominal DH, q) (what its controller believes) plus repeatability noise; the sensor reads
s = T⁻¹(p) + field(p) + noise. A check row's robot reading is b at its point (the truth `rrbc calibrate` scores
against); a target row has no robot reading.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from rrbc_core.io.measurements import MeasurementSet
from rrbc_core.io.measurements_write import write_measurements
from rrbc_core.simulation.kinematics import UR5, UR5_TOOL_DOWN_SEED, forward, perturbed


def joint_file(
    path: Path,
    seed: int,
    dh_size: float = 1.0,
    field_mm: float = 0.0,
    noise_mm: float = 0.02,
    n_reg: int = 8,
    n_fid: int = 30,
    n_chk: int = 30,
    n_tgt: int = 3,
    tool_mm: float = 100.0,
) -> Path:
    from rrbc_core.simulation.errorterms import SmoothField

    rng = np.random.default_rng(seed)
    nominal = UR5.with_tool(tool_mm)
    true = perturbed(nominal, rng, 0.1 * dh_size, 0.2 * dh_size, 0.05 * dh_size)
    rot = Rotation.from_rotvec(rng.normal(size=3) * 0.3).as_matrix()  # sensor -> robot
    t = np.array([1100.0, -450.0, 1250.0])
    field = SmoothField(rms_mm=max(field_mm, 1e-9), length_mm=300.0, seed=seed) if field_mm > 0 else None
    n = n_reg + n_fid + n_chk + n_tgt
    q = UR5_TOOL_DOWN_SEED + rng.uniform(-0.7, 0.7, (n, 6))
    p, _ = forward(true, q)
    b_nom, _ = forward(nominal, q)
    s = (p - t) @ rot  # robot -> sensor frame
    if field is not None:
        s = s + field.displacement_at(s) if hasattr(field, "displacement_at") else s + _field(field, s)
    s = s + rng.normal(0, noise_mm, s.shape)
    b = b_nom + rng.normal(0, noise_mm, b_nom.shape)
    roles = ["registration"] * n_reg + ["fiducial"] * n_fid + ["check"] * n_chk + ["target"] * n_tgt
    ids = [f"{r[0].upper()}{i + 1}" for i, r in enumerate(roles)]
    b[len(roles) - n_tgt :] = np.nan
    mset = MeasurementSet(
        ids=tuple(ids),
        roles=tuple(roles),
        sensor=s,
        robot=b,
        time=np.full(n, np.nan),
        lines=tuple(0 for _ in ids),
        source=str(path),
        extra={f"q{j + 1}": tuple(repr(float(v)) for v in np.degrees(q[:, j])) for j in range(6)},
    )
    write_measurements(path, mset)
    return path


def _field(term, s):
    from rrbc_core.simulation.errormodels import PointSet

    pts = PointSet(robot=s, sensor=s, time=np.zeros(len(s)), tool_rotation=None, joint_seed=None)
    return term.sample(pts, "sensor", None, 1)[0]
