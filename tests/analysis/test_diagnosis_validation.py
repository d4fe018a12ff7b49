"""Issue 6, "done when": the RRBC recommendation of `rrbc diagnose` matches what RRBC actually does to held-out
points.

Each seeded synthetic data set has paired rows (role `both`: registration and fiducial) and held-out `check`
rows with their truth. `diagnose` sees only the paired rows (a user has no truth); `correct_measurements` runs
RRBC (least-squares registration, IDW k=4 p=2 over the fiducials) and scores the checks. The verdict agrees when
`recommended` == (RMST of the checks with RRBC < RMST with the rigid registration alone).

Two classes of 20 data sets each:
  * bias-dominated: a smooth robot-side field (RMS 5-15 x the noise sigma, correlation length 0.3-0.6 x the
    extent), in half of the sets together with a uniform scale; RRBC should help and be recommended;
  * noise-only: rigid + isotropic sensor noise; RRBC only adds interpolated noise and should not be recommended.
Point counts 30-80 paired + 20 checks, planar or volumetric, sigma 0.01-0.05 mm.

Allowance: the issue's goal is agreement at least 9 times in 10, applied per class: at least 18 of 20.
Measured (these seeds, least-squares + IDW k=4 p=2): 20 of 20 bias-dominated sets agree (expected RMST change
from leave-one-out -36 % to -63 %; measured on the checks -32 % to -70 %) and 19 of 20 noise-only sets agree
(expected change +9 % to +31 %); the one disagreement (seed 62007) is a noise-only set where RRBC lowered the check
RMST by 1.4 % (0.0730 -> 0.0720 mm), within the scatter of 20 check points, while diagnose said +31 %.
"""

import numpy as np
from scipy.spatial.transform import Rotation

from rrbc_core.analysis.diagnosis import diagnose
from rrbc_core.correction.pipeline import correct_measurements
from rrbc_core.io.measurements import MeasurementSet
from rrbc_core.methods import MethodOptions
from rrbc_core.models.errormodels import PointSet
from rrbc_core.models.errorterms import Scale, SmoothField

SETS_PER_CLASS = 20
MIN_AGREE = 18  # 9 in 10


def _data_set(seed: int, biased: bool):
    """(mset with paired + check rows, mset with the paired rows only)."""
    rng = np.random.default_rng(seed)
    n_pair, n_check = int(rng.integers(30, 81)), 20
    planar = bool(rng.integers(2))
    sigma = float(rng.uniform(0.01, 0.05))
    ext = float(rng.uniform(300, 800))
    lo = np.array([500.0, 0.0, 300.0]) - ext / 2
    pair = rng.uniform(0, ext, (n_pair, 3)) + lo
    check = rng.uniform(0.1 * ext, 0.9 * ext, (n_check, 3)) + lo  # inside the paired points' region
    robot = np.vstack([pair, check])
    if planar:
        robot[:, 2] = 300.0
    n = len(robot)
    rot = Rotation.random(random_state=rng).as_matrix()
    sensor = robot @ rot
    sensor = sensor - sensor.mean(axis=0) + np.array([0.0, 0.0, 2000.0])
    time = rng.permutation(n).astype(float) * 10.0
    disp = np.zeros((n, 3))
    if biased:
        ps = PointSet(robot=robot, sensor=sensor, time=time)
        field = SmoothField(
            rms_mm=sigma * rng.uniform(5, 15), length_mm=ext * rng.uniform(0.3, 0.6), seed=int(rng.integers(2**31))
        )
        disp += field.sample(ps, "robot", rng, 1)[0]
        if seed % 2:
            disp += Scale(float(rng.choice([-1, 1]) * rng.uniform(100, 300))).sample(ps, "robot", rng, 1)[0]
    s = sensor + rng.normal(0.0, sigma, (n, 3))
    r = robot + disp
    ids = [f"P{i}" for i in range(n_pair)] + [f"C{i}" for i in range(n_check)]
    roles = ["both"] * n_pair + ["check"] * n_check
    full = MeasurementSet(ids, roles, s, r, time, [0] * n)
    paired = MeasurementSet(ids[:n_pair], roles[:n_pair], s[:n_pair], r[:n_pair], time[:n_pair], [0] * n_pair)
    return full, paired


def _agreements(biased: bool, base: int):
    agree = []
    for k in range(SETS_PER_CLASS):
        full, paired = _data_set(base + k, biased)
        rec = diagnose(paired).rrbc_recommended
        summ = correct_measurements(full, MethodOptions()).summary()
        helped = summ["rmst_rrbc_mm"] < summ["rmst_rigid_mm"]
        agree.append(rec == helped)
    return agree


def test_rrbc_recommendation_matches_held_out_checks_on_bias_dominated_data():
    agree = _agreements(True, 61_000)
    assert sum(agree) >= MIN_AGREE, agree


def test_rrbc_recommendation_matches_held_out_checks_on_noise_only_data():
    agree = _agreements(False, 62_000)
    assert sum(agree) >= MIN_AGREE, agree
