"""Joint values in measurement files: the robot's configuration at which each row was measured (checks and targets:
the configuration that will be used to reach them). docs/formats/measurement-file.md, "Joint values".

Two spellings, one reader (`joint_values`), both read through the robot model (`models.chain.Chain`) that names its
columns:

- a URDF's actuated joints (not fixed, not mimic), one column each, named exactly after the joint, in ROS JointState
  units: radians for revolute and continuous joints, metres for prismatic ones. Every value must lie within the
  joint's URDF limits (a revolute value beyond them is most often degrees where radians are due); a continuous joint
  has no limits, and a value beyond ±4π (two turns) is refused as likely degrees;
- the DH arms' columns `q1` … `q6` in degrees (`--robot ur5|ur10`). A file whose every angle lies within ±2π looks
  like radians and is refused (a real arm's configurations span more than ±6.3° on some joint).

All of a model's columns or none; on every row a finite number.
"""

from __future__ import annotations

import difflib
import math

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.io.measurements import MeasurementSet
from rrbc_core.models.chain import Chain

CONTINUOUS_MAX_RAD = 4 * math.pi  # a continuous joint's value beyond two turns: likely degrees


def _cell(mset: MeasurementSet, col: str, i: int, unit: str) -> float:
    text = str(mset.extra[col][i]).strip()
    try:
        v = float(text) if text.isascii() else math.nan
    except ValueError:
        v = math.nan
    if not math.isfinite(v) or abs(v) > 1e6:
        raise InputError(f"{mset.source}: {_where(mset, i)}: {col} {text[:20]!r} is not a finite number ({unit})")
    return v


def _where(mset: MeasurementSet, i: int) -> str:
    line = mset.lines[i] if i < len(mset.lines) else 0
    return f"line {line}" if line else f"row {i + 1}"


def _missing(mset: MeasurementSet, chain: Chain, missing: list[str]) -> InputError:
    others = [c for c in mset.extra if c not in chain.columns]
    hints = []
    for m in missing:
        close = difflib.get_close_matches(m, others, n=1, cutoff=0.6)
        if close:
            hints.append(f"{close[0]!r} for {m!r}?")
    units = sorted({"degrees" if i.unit == "deg" else "radians" if i.unit == "rad" else "metres" for i in chain.inputs})
    return InputError(
        f"{mset.source}: joint columns {', '.join(missing)} missing for {chain.name}"
        + (f" (the file has {' '.join(hints)})" if hints else "")
        + f"; give all {len(chain.columns)} of its joint columns, named exactly ({', '.join(units)}), or none"
    )


def joint_values(mset: MeasurementSet, chain: Chain) -> np.ndarray | None:
    """(R, I) the chain's input values per file row, in rad (revolute) or mm (prismatic), `chain.inputs` order, or
    None when the file has none of the chain's joint columns.

    Raises
    ------
    InputError
        Some columns missing (with the closest column names the file has), a value that is not a finite number, a
        value outside its joint's limits, or angles in the wrong unit (module docstring).
    """
    have = [c for c in chain.columns if c in mset.extra]
    if not have:
        return None
    if len(have) != len(chain.columns):
        raise _missing(mset, chain, [c for c in chain.columns if c not in mset.extra])
    n = len(mset.ids)
    raw = np.empty((n, len(chain.inputs)))
    for j, inp in enumerate(chain.inputs):
        for i in range(n):
            raw[i, j] = _cell(mset, inp.column, i, inp.unit)
    if all(inp.unit == "deg" for inp in chain.inputs):
        if n and np.abs(raw).max() <= 2 * np.pi + 1e-9:
            raise InputError(
                f"{mset.source}: every joint angle is within ±2π: these look like radians; give "
                f"{'..'.join((chain.columns[0], chain.columns[-1]))} in degrees"
            )
    q = raw * np.array([inp.scale for inp in chain.inputs])
    for j, inp in enumerate(chain.inputs):
        col = q[:, j]
        if inp.lower is not None and inp.upper is not None:
            tol = 1e-6 * max(1.0, abs(inp.lower), abs(inp.upper))
            bad = np.flatnonzero((col < inp.lower - tol) | (col > inp.upper + tol))
            if len(bad):
                i = int(bad[0])
                lo, hi = inp.lower / inp.scale, inp.upper / inp.scale
                as_degrees = np.radians(raw[:, j])
                in_degrees = bool(np.all((as_degrees >= inp.lower - tol) & (as_degrees <= inp.upper + tol)))
                hint = " (degrees where radians are due?)" if inp.unit == "rad" and in_degrees else ""
                raise InputError(
                    f"{mset.source}: {_where(mset, i)}: {inp.column} = {raw[i, j]:g} {inp.unit} is outside the joint's "
                    f"limits [{lo:g}, {hi:g}] {inp.unit}{hint}; {len(bad)} row(s) so"
                )
        elif inp.kind == "continuous":
            bad = np.flatnonzero(np.abs(col) > CONTINUOUS_MAX_RAD)
            if len(bad):
                i = int(bad[0])
                raise InputError(
                    f"{mset.source}: {_where(mset, i)}: {inp.column} = {raw[i, j]:g} rad is more than two turns: "
                    "degrees where radians are due? (ROS JointState units: rad, m)"
                )
    return q


def joint_angles(mset: MeasurementSet) -> np.ndarray | None:
    """(R, 6) the q1..q6 columns in radians (read as degrees), or None when the file has none of them: the DH arms'
    spelling, read through the UR5's chain (the columns and their checks are the same for every DH arm)."""
    from rrbc_core.models.kinematics import UR5

    return joint_values(mset, Chain.from_dh(UR5, "ur5"))


TOOL_COLUMNS = ("tool_x", "tool_y", "tool_z")


def file_tool(mset: MeasurementSet) -> tuple[float, float, float] | None:
    """The tool point (3,) mm in the tip link's (a DH arm's flange's) frame that the file records in its columns
    `tool_x`, `tool_y`, `tool_z` (what `rrbc simulate --out` writes for a scene with an arm), or None without them.
    Commands use it when no `--tool` is given.

    Raises
    ------
    InputError
        Only some of the columns, a value that is not a finite number, or rows that disagree (one tool per file).
    """
    have = [c for c in TOOL_COLUMNS if c in mset.extra]
    if not have:
        return None
    if len(have) != 3:
        missing = ", ".join(c for c in TOOL_COLUMNS if c not in have)
        raise InputError(f"{mset.source}: the tool columns come as tool_x, tool_y, tool_z together; missing {missing}")
    vals = np.empty((len(mset), 3))
    for j, col in enumerate(TOOL_COLUMNS):
        for i in range(len(mset)):
            vals[i, j] = _cell(mset, col, i, "mm")
    if len(vals) and np.ptp(vals, axis=0).max() > 1e-6:
        raise InputError(f"{mset.source}: the tool columns differ between rows; one tool per file (or give --tool)")
    return (float(vals[0, 0]), float(vals[0, 1]), float(vals[0, 2])) if len(vals) else None
