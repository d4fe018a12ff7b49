"""The corrected targets and checks as a CSV a robot program or a spreadsheet reads (`rrbc correct --out`).

One row per target and check, in the order `rrbc correct --json` lists them (stations in file order):

- `id`, `role` (target or check), `group` (only for a file with stations);
- `robot_x`, `robot_y`, `robot_z`: the corrected robot-frame position the robot is sent to (mm; RRBC with the
  interpolation used, or the rigid one with `--interpolation none`);
- `bound95_mm`: the 95 % bound on that position's 3-D error (empty where none can be given);
- `extrapolated`: `true` outside the fiducials' hull.

The rows are built from the JSON object of `rrbc correct` itself (`corrected_rows`), so the file and `--json` give the
same numbers. Floats are written with `repr` (reading back gives the very same floats). The file is written
atomically (`io.measurements_write.atomic_write_text`).
"""

from __future__ import annotations

import csv
import io
from os import PathLike

from rrbc_core.io.measurements_write import atomic_write_text

COLUMNS = ("id", "role", "robot_x", "robot_y", "robot_z", "bound95_mm", "extrapolated")


def corrected_rows(result_json: dict) -> list[dict]:
    """The rows (module docstring) of `rrbc correct --json`'s object (a file with or without stations)."""
    parts = result_json["groups"] if "groups" in result_json else [result_json]
    rows = []
    for part in parts:
        for role, key in (("target", "targets"), ("check", "checks")):
            for p in part.get(key) or []:
                pos = p["robot_rrbc"]
                row = {"id": p["id"], "role": role}
                if "group" in part:
                    row["group"] = part["group"]
                row.update({"robot_x": pos[0], "robot_y": pos[1], "robot_z": pos[2]})
                row["bound95_mm"] = p.get("bound95_mm")
                row["extrapolated"] = bool(p.get("extrapolated", False))
                rows.append(row)
    return rows


def corrected_csv(result_json: dict) -> str:
    """The CSV text of `corrected_rows` (a `group` column after `role` when the file has stations)."""
    rows = corrected_rows(result_json)
    columns = list(COLUMNS)
    if "groups" in result_json:
        columns.insert(2, "group")
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(columns)
    for r in rows:
        cells = []
        for c in columns:
            v = r.get(c)
            if v is None:
                cells.append("")
            elif isinstance(v, bool):
                cells.append("true" if v else "false")
            elif isinstance(v, float):
                cells.append(repr(v))
            else:
                cells.append(str(v))
        w.writerow(cells)
    return out.getvalue()


def write_corrected(path: str | PathLike, result_json: dict) -> int:
    """Write `corrected_csv` to `path` atomically; returns the number of rows written."""
    atomic_write_text(path, corrected_csv(result_json))
    return len(corrected_rows(result_json))
