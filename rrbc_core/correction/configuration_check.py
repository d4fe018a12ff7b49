"""Are the checks and targets reached in the arm configurations their nearest fiducials were measured in?
(`rrbc calibrate`'s warning, and `rrbc correct`'s on a file with the DH arms' joint columns q1..q6, issue 38.)

RRBC interpolates the fiducials' corrections by position. An arm's error depends on its joint configuration (the
same place reached with the tool turned, or the wrist flipped, is another error), so where a point is reached in
configurations unlike those of the fiducials around it, RRBC's correction there comes from other configurations:
on real arms it was then 11-40 % worse than rigid, silently. VEC follows the configuration.

The test, with no threshold of our own: for every check and target row, its configuration distance is the
smallest, over its `NEIGHBOURS` nearest fiducials in the sensor frame (the ones RRBC's IDW weighs most), of the
largest change of one revolute joint (rad, wrapped to ±π; prismatic joints are left out: mm do not compare with
rad). The fiducials' own distances (each to its nearest other fiducials, as in leave-one-out) are what RRBC's
cross-validation saw. A one-sided Mann-Whitney test asks whether the points' distances are larger (`ALPHA`); when
they are, the warning says how many points lie beyond the largest distance any fiducial had.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: the nearest fiducials a point's configuration is compared with (RRBC's IDW uses 4)
NEIGHBOURS = 4
#: the one-sided Mann-Whitney test's false-alarm rate
ALPHA = 0.01


@dataclass(frozen=True)
class ConfigurationCheck:
    """Per check and target row `distance_rad` (M,), the fiducials' own (F,), the test's `p_value`, `beyond` (M,)
    bool: farther than any fiducial's own; `flagged`: the test rejected at `ALPHA`."""

    distance_rad: np.ndarray
    fiducial_rad: np.ndarray
    p_value: float
    beyond: np.ndarray
    flagged: bool

    def warning(self, advice: str = "VEC follows the configuration", space: str = "position") -> str | None:
        """The warning's words when `flagged`, else None; `advice` ends it. `space`: what RRBC interpolates over
        (`rrbc calibrate` may interpolate over the joints, `analysis.configuration_rrbc`)."""
        if not self.flagged:
            return None
        n, m = int(self.beyond.sum()), len(self.distance_rad)
        how = (
            "RRBC interpolates by position only, so where the arm's error depends on its configuration its "
            "correction there comes from other configurations"
            if space == "position"
            else "RRBC interpolates over the fiducials' configurations, and none is near theirs, so its correction "
            "there is carried from other configurations"
        )
        return (
            f"{n} of {m} checks and targets are reached in joint configurations farther from those of their nearest "
            f"fiducials (up to {np.degrees(self.distance_rad.max()):.0f}° in one joint) than any fiducial is from its "
            f"neighbours' ({np.degrees(self.fiducial_rad.max()):.0f}°; one-sided Mann-Whitney p = {self.p_value:.2g}):"
            f" {how} and can be worse than rigid; {advice}"
        )


def _nearest_change(q: np.ndarray, neighbours: np.ndarray) -> np.ndarray:
    """(M,) per configuration q (M, J), the smallest over its neighbours' configurations (M, K, J) of the largest
    wrapped change of one joint, rad."""
    d = np.abs((q[:, None, :] - neighbours + np.pi) % (2 * np.pi) - np.pi)
    return d.max(axis=2).min(axis=1)


def configuration_check(
    sensor: np.ndarray, q: np.ndarray, revolute: np.ndarray, rows_fid: np.ndarray, rows_pts: np.ndarray
) -> ConfigurationCheck | None:
    """The check (module docstring) for `rows_pts` (checks and targets) against `rows_fid`, from the file's sensor
    readings (R, 3) mm, joint values q (R, I) (rad or mm) and which inputs are `revolute` (I,) bool. None when it
    cannot run: no revolute joint, fewer than NEIGHBOURS + 2 fiducials, or no points."""
    from scipy.spatial import cKDTree
    from scipy.stats import mannwhitneyu

    rev = np.asarray(revolute, bool)
    rows_fid, rows_pts = np.asarray(rows_fid, int), np.asarray(rows_pts, int)
    if not rev.any() or len(rows_fid) < NEIGHBOURS + 2 or len(rows_pts) == 0:
        return None
    s = np.asarray(sensor, float)
    qr = np.asarray(q, float)[:, rev]
    tree = cKDTree(s[rows_fid])
    _, near = tree.query(s[rows_pts], k=NEIGHBOURS)
    dist = _nearest_change(qr[rows_pts], qr[rows_fid[near]])
    _, near_f = tree.query(s[rows_fid], k=NEIGHBOURS + 1)  # itself first
    own = _nearest_change(qr[rows_fid], qr[rows_fid[near_f[:, 1:]]])
    p = float(mannwhitneyu(dist, own, alternative="greater").pvalue)
    return ConfigurationCheck(dist, own, p, dist > own.max(), bool(p < ALPHA))


def file_configuration_check(mset) -> ConfigurationCheck | None:
    """`configuration_check` on a measurement file's own rows (fiducial and both against check and target) when it
    has the DH arms' joint columns q1..q6 (degrees, six revolute joints: docs/formats/measurement-file.md); None
    without them, or when they cannot be read as such (then `rrbc calibrate`, given the arm, reads and checks them).
    What `rrbc correct` warns with: it has no arm model, and a URDF's joint names and kinds are not known to it."""
    from rrbc_core.errors import InputError
    from rrbc_core.io.joints import joint_values
    from rrbc_core.models.chain import Chain
    from rrbc_core.models.kinematics import UR5

    if mset is None or not all(f"q{i}" in mset.extra for i in range(1, 7)):
        return None
    try:
        q = joint_values(mset, Chain.from_dh(UR5, "dh"))
    except InputError:
        return None
    if q is None:
        return None
    pts = np.concatenate([mset.rows("check"), mset.rows("target")]).astype(int)
    return configuration_check(mset.sensor, q, np.ones(q.shape[1], bool), np.asarray(mset.rows("fiducial")), pts)
