"""Simulated measurements of an arm described by a chain (`models.chain.Chain`, from a URDF or a DH table), with its
joint columns: what the URDF calibration tests, the calibration benchmark and the examples measure on.

Physics (seeded): the true arm is the nominal chain with kinematic errors (`random_errors`: joint offsets, origin
errors, tool) of a given size; it reaches each point at random joint values within the joints' limits
(`random_poses`); the sensor reads the point (a random sensor pose; optionally a smooth field of position; noise);
the robot columns are the nominal controller's position of the same joints (plus noise): what a controller reports.
"""

from __future__ import annotations

import numpy as np

from rrbc_core.io.measurements import MeasurementSet
from rrbc_core.models.chain import Chain


def random_poses(chain: Chain, rng: np.random.Generator, n: int, spread: float = 0.6) -> np.ndarray:
    """(n, I) joint values (rad, mm) drawn uniformly over the middle `spread` of each joint's range (±π·spread for
    a joint without limits)."""
    q = np.empty((n, len(chain.inputs)))
    for i, inp in enumerate(chain.inputs):
        lo, hi = (-np.pi, np.pi) if inp.lower is None or inp.upper is None else (inp.lower, inp.upper)
        mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo) * spread
        q[:, i] = rng.uniform(mid - half, mid + half, n)
    return q


def random_errors(chain: Chain, rng: np.random.Generator, size: float = 1.0) -> np.ndarray:
    """Kinematic errors (P,) in `chain.param_names` order: angles N(0, (0.05° · size)²) rad, lengths N(0, (0.2 mm ·
    size)²) — the size of a real arm's calibration errors."""
    sd = np.where(chain.angular, np.radians(0.05) * size, 0.2 * size)
    return rng.normal(0.0, sd)


def chain_measurements(
    chain: Chain,
    seed: int,
    *,
    kin_size: float = 1.0,
    field_mm: float = 0.0,
    noise_mm: float = 0.02,
    n_reg: int = 8,
    n_fid: int = 40,
    n_chk: int = 30,
    n_tgt: int = 3,
    both_first: int = 0,
    source: str = "<simulated>",
    q_override: np.ndarray | None = None,
    stations: int = 1,
    compliance: dict | None = None,
    gravity=None,
    arm_seed: int | None = None,
) -> MeasurementSet:
    """A measurement set with the chain's joint columns (ROS units: rad, m; q1..q6 degrees for a DH chain): the true
    arm (the nominal one with `random_errors` of `kin_size`) reaches each point at random joints; the sensor reads it
    (a random pose, plus a smooth field of `field_mm` RMS, plus noise); the robot columns are the nominal controller's
    positions of the same joints, plus noise. `both_first`: that many registration rows come first with role `both`.
    `q_override`: joint values written to the file instead of the ones measured (another robot's, say).
    `stations` > 1: that many stationings in one file (a `group` column, rows dealt round-robin, every role in each),
    the instrument at another pose for each, the arm's errors the same. `compliance`: load terms the true arm has,
    name -> coefficient (`models.loads`: `<joint>.compliance` rad/Nm, ...), under `gravity` (m/s², base frame)."""
    from scipy.spatial.transform import Rotation

    from rrbc_core.models.errormodels import PointSet
    from rrbc_core.models.errorterms import SmoothField

    rng = np.random.default_rng(seed)
    truth = random_errors(chain, rng, kin_size)
    if arm_seed is not None:
        truth = random_errors(chain, np.random.default_rng(arm_seed), kin_size)
    n = n_reg + n_fid + n_chk + n_tgt
    q = random_poses(chain, rng, n)
    dv = drot = None
    if compliance:
        from rrbc_core.models.loads import deflections, gravity_loads, named_terms

        terms = named_terms(chain, list(compliance))
        dv, drot = deflections(chain, terms, list(compliance.values()), gravity_loads(chain, q, gravity))
    p = chain.kinematics(q, truth, jacobians=False, dv=dv, drot=drot)[0]
    rot = Rotation.from_rotvec(rng.normal(size=3) * 0.3).as_matrix()
    t = np.array([900.0, -400.0, 1200.0])
    s = (p - t) @ rot
    station = np.arange(n) % max(int(stations), 1)
    for g in range(1, max(int(stations), 1)):  # the instrument moved for each further station
        rg = Rotation.from_rotvec(rng.normal(size=3) * 0.3).as_matrix()
        tg = t + rng.normal(0, 200.0, 3)
        s[station == g] = (p[station == g] - tg) @ rg
    if field_mm > 0:
        pts = PointSet(robot=s, sensor=s, time=np.zeros(len(s)), tool_rotation=None, joint_seed=None)
        s = (
            s
            + SmoothField(rms_mm=field_mm, length_mm=300.0, seed=seed).sample(
                pts, "sensor", np.random.default_rng(seed), 1
            )[0]
        )
    s = s + rng.normal(0, noise_mm, s.shape)
    b = chain.forward(q) + rng.normal(0, noise_mm, p.shape)
    roles = ["registration"] * n_reg + ["fiducial"] * n_fid + ["check"] * n_chk + ["target"] * n_tgt
    for i in range(both_first):
        roles[i] = "both"
    ids = [f"{r[0].upper()}{i + 1}" for i, r in enumerate(roles)]
    b[n - n_tgt :] = np.nan
    written = q if q_override is None else q_override
    extra = {inp.column: tuple(repr(float(v)) for v in written[:, i] / inp.scale) for i, inp in enumerate(chain.inputs)}
    if stations > 1:
        extra["group"] = tuple(f"station{g + 1}" for g in station)
    return MeasurementSet(
        ids=tuple(ids),
        roles=tuple(roles),
        sensor=s,
        robot=b,
        time=np.full(n, np.nan),
        lines=tuple(0 for _ in ids),
        source=source,
        extra=extra,
    )
