"""The targets file of `rrbc scene new`: a CSV with columns `id,x,y,z` and optionally `region_mm` (robot frame,
millimetres; docs/formats/targets-file.md).

    id,x,y,z,region_mm
    H1,400,-150,15,4
    H2,400,-50,15,

`region_mm` is the full edge of a cubic region of variability (default `DEFAULT_REGION_MM`). Refused with one
line naming the file and row: a missing column, a non-number, a duplicate id, non-ASCII digits, coordinates
that look like metres (every |coordinate| below `METRES_BELOW_MM` mm: a cell in millimetres spans more), and
files beyond `MAX_TARGETS` rows.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rrbc_core.errors import InputError

DEFAULT_REGION_MM = 4.0
METRES_BELOW_MM = 5.0
MAX_TARGETS = 500
MAX_BYTES = 1 << 20
REQUIRED = ("id", "x", "y", "z")


@dataclass(frozen=True, eq=False)
class TargetList:
    """Targets: `ids` (M,), `positions` (M, 3) robot frame, mm, `region_mm` (M,) full cube edges, mm."""

    ids: tuple
    positions: np.ndarray
    region_mm: np.ndarray
    source: str


def _number(text: str, where: str, name: str) -> float:
    s = text.strip()
    if not s.isascii():
        raise InputError(f"{where}: {name} {s[:20]!r} is not an ASCII number (mm)")
    try:
        v = float(s)
    except ValueError:
        raise InputError(f"{where}: {name} {s[:20]!r} is not a number (mm)") from None
    if not math.isfinite(v) or abs(v) > 1e7:
        raise InputError(f"{where}: {name} {s[:20]!r} must be a finite number of mm below 1e7")
    return v


def read_targets(path) -> TargetList:
    """Read and check a targets CSV (module docstring). Raises InputError with one actionable line."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: targets file not found")
    if p.stat().st_size > MAX_BYTES:
        raise InputError(f"{p}: targets file larger than {MAX_BYTES // 1024} KiB; at most {MAX_TARGETS} targets")
    try:
        text = p.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError:
        raise InputError(f"{p}: not a UTF-8 text file (expected CSV with columns id,x,y,z[,region_mm])") from None
    rows = list(csv.reader(io.StringIO(text)))
    rows = [r for r in rows if any(c.strip() for c in r) and not r[0].lstrip().startswith("#")]
    if not rows:
        raise InputError(f"{p}: empty; expected a header id,x,y,z[,region_mm] and one row per target")
    head = [h.strip().lower() for h in rows[0]]
    missing = [c for c in REQUIRED if c not in head]
    if missing:
        raise InputError(
            f"{p}: line 1: missing column(s) {', '.join(missing)}; expected id,x,y,z[,region_mm], got {','.join(head)[:80]}"
        )
    if len(rows) - 1 > MAX_TARGETS:
        raise InputError(f"{p}: {len(rows) - 1} targets; at most {MAX_TARGETS}")
    col = {name: head.index(name) for name in head}
    ids, pos, reg = [], [], []
    for k, r in enumerate(rows[1:], start=2):
        where = f"{p}: row {k}"
        if len(r) < len(head):
            r = r + [""] * (len(head) - len(r))
        pid = r[col["id"]].strip()
        if not pid or not pid.isprintable() or len(pid) > 64:
            raise InputError(f"{where}: id must be 1-64 printable characters")
        if pid in ids:
            raise InputError(f"{where}: duplicate id {pid!r}")
        xyz = [_number(r[col[a]], where, a) for a in ("x", "y", "z")]
        region = DEFAULT_REGION_MM
        if "region_mm" in col and r[col["region_mm"]].strip():
            region = _number(r[col["region_mm"]], where, "region_mm")
            if not region > 0:
                raise InputError(f"{where}: region_mm must be > 0 (the full edge of the target's region, mm)")
        ids.append(pid)
        pos.append(xyz)
        reg.append(region)
    if not ids:
        raise InputError(f"{p}: no targets (only a header)")
    positions = np.array(pos, float)
    if np.abs(positions).max() < METRES_BELOW_MM:
        raise InputError(
            f"{p}: every coordinate is below {METRES_BELOW_MM:g} in size: these look like metres; give the targets "
            "in millimetres (multiply by 1000)"
        )
    return TargetList(tuple(ids), positions, np.array(reg, float), str(p))
