"""Joint angles in measurement files: the optional columns `q1` … `q6`, degrees, the arm's joint configuration at
which the row was measured by the robot (checks and targets: the configuration that will be used to reach them).
docs/formats/measurement-file.md, "Joint angles".

All six columns or none; on every row a finite number of degrees. A file whose every angle lies within ±2π looks
like radians and is refused (a real arm's configurations span more than ±6.3° on some joint).
"""

from __future__ import annotations

import math

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.io.measurements import MeasurementSet

JOINT_COLUMNS = tuple(f"q{i + 1}" for i in range(6))


def joint_angles(mset: MeasurementSet) -> np.ndarray | None:
    """(R, 6) joint angles in radians, one row per file row, or None when the file has no joint columns."""
    have = [c for c in JOINT_COLUMNS if c in mset.extra]
    if not have:
        return None
    if len(have) != 6:
        missing = [c for c in JOINT_COLUMNS if c not in mset.extra]
        raise InputError(
            f"{mset.source}: joint columns {', '.join(missing)} missing; give all of q1..q6 (degrees) or none"
        )
    q = np.empty((len(mset.ids), 6))
    for j, col in enumerate(JOINT_COLUMNS):
        for i, text in enumerate(mset.extra[col]):
            s = str(text).strip()
            line = mset.lines[i] if i < len(mset.lines) else 0
            try:
                v = float(s) if s.isascii() else math.nan
            except ValueError:
                v = math.nan
            if not math.isfinite(v) or abs(v) > 1e4:
                where = f"line {line}" if line else f"row {i + 1}"
                raise InputError(f"{mset.source}: {where}: {col} {s[:20]!r} is not a finite number of degrees")
            q[i, j] = v
    if len(q) and np.abs(q).max() <= 2 * np.pi + 1e-9:
        raise InputError(
            f"{mset.source}: every joint angle is within ±2π: these look like radians; give q1..q6 in degrees"
        )
    return np.radians(q)
