"""A measurement plan: the points to measure in a cell, as a measurement file whose readings are left empty to fill
(docs/formats/measurement-file.md, "Measurement plans").

Columns: the measurement file's (`id, role, sensor_x…z, robot_x…z`) with the readings empty, then `planned_x,
planned_y, planned_z` — where to take the point, robot base frame, mm. Rows: the registration points, then the
fiducials, then the targets, each group in a short path (nearest neighbour from the point nearest the robot's
base, which is at the origin). Fill the sensor and robot readings (targets: sensor only) and the file reads as a
measurement file; the planned columns are kept as extra columns.
"""

from __future__ import annotations

import csv
import io

import numpy as np

from rrbc_core.io.measurements import ROBOT_COLUMNS, SENSOR_COLUMNS

PLANNED_COLUMNS = ("planned_x", "planned_y", "planned_z")
ROLE_OF = {"registration": "registration", "fiducials": "fiducial", "targets": "target"}


def tour(points) -> np.ndarray:
    """Order (P,) of `points` (P, 3): nearest neighbour from the point nearest the origin."""
    p = np.asarray(points, float).reshape(-1, 3)
    if not len(p):
        return np.zeros(0, int)
    left = list(range(len(p)))
    cur = int(np.argmin(np.linalg.norm(p, axis=1)))
    order = [cur]
    left.remove(cur)
    while left:
        d = np.linalg.norm(p[left] - p[cur], axis=1)
        cur = left.pop(int(np.argmin(d)))
        order.append(cur)
    return np.array(order, int)


def plan_rows(groups: dict) -> list[tuple[str, str, np.ndarray]]:
    """(id, role, planned position) rows in measuring order, from {"registration"/"fiducials"/"targets": (ids,
    (K, 3) positions)}."""
    rows = []
    for kind in ("registration", "fiducials", "targets"):
        ids, pos = groups.get(kind, ((), np.zeros((0, 3))))
        pos = np.asarray(pos, float).reshape(-1, 3)
        for i in tour(pos):
            rows.append((str(ids[i]), ROLE_OF[kind], pos[i]))
    return rows


def plan_csv(groups: dict, comments=()) -> str:
    """The plan's text (module docstring)."""
    out = io.StringIO()
    for line in comments:
        out.write(f"# {line}\n")
    w = csv.writer(out, lineterminator="\n")
    w.writerow(["id", "role", *SENSOR_COLUMNS, *ROBOT_COLUMNS, *PLANNED_COLUMNS])
    for pid, role, p in plan_rows(groups):
        w.writerow([pid, role, "", "", "", "", "", "", *(repr(float(v)) for v in p)])
    return out.getvalue()
