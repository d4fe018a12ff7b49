"""Stationing data of a mobile manipulator measured by a total station, read from its YAML form into a measurement
set (docs/real_data.md).

The form is the one of the public "construction robot stationing datasets" (Hilti Research, a lift-column arm with a
prism measured by a total station): a file holds the robot's joint names and, per column height and per solution
space of the arm, a list of stationing measurements (the points a station is registered on) and a list of
evaluation measurements (the points it is scored on). Each measurement gives the joint states (URDF units: metres,
radians), the prism's position measured by the instrument (metres, instrument frame), an id and a time::

    joint_names: [column_prismatic_joint, dsr_joint1, ...]
    column_heights:
      1.98:
        solution_spaces:
          0:
            stationing_measurements:
            - {id: 0, time: 1709561629.9, joint_states: [...], prism_position: [7.33, 5.83, 1.17]}
            evaluation_measurements: [...]

What rrbc makes of it (one `MeasurementSet`, mm and s): one station (`group` column ``h<height>_s<space>``) per
height and solution space that has stationing measurements (the others cannot be registered and are left out);
``sensor_*`` the prism as the instrument measured it; ``robot_*`` the prism as the robot's nominal model places it,
the URDF chain's forward kinematics of the joint states (``models.chain.Chain.forward``: the robot frame is the
chain's base link); the joint columns kept as written; ids ``S<id>`` for stationing and ``E<id>`` for evaluation
measurements. The roles (`FIDUCIAL_CHOICES`):

- ``stationing``: stationing points are `both` (registration and fiducial), evaluation points `check` — RRBC as a
  site would run it, its fiducials all on the stationing board;
- ``half`` / ``half-swapped``: as ``stationing``, and every other evaluation point of each station (the even-numbered
  ones, or the odd-numbered) is a `fiducial` too, the rest `check` — fiducials around the checks, the two halves
  scoring each other.
"""

from __future__ import annotations

import math
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.io.groups import GROUP_COLUMN
from rrbc_core.io.measurements import MeasurementSet
from rrbc_core.models.chain import Chain

__all__ = ["FIDUCIAL_CHOICES", "YAML_LIMIT_BYTES", "read_stationing_yaml"]

FIDUCIAL_CHOICES = ("stationing", "half", "half-swapped")
YAML_LIMIT_BYTES = 64 * 2**20  # a stationing file is read only up to this size (the public ones are 0.26 MB)


def _load(path: Path) -> Any:
    import yaml  # PyYAML: only this reader needs it

    if not path.is_file():
        raise InputError(f"{path}: no such file")
    if path.stat().st_size > YAML_LIMIT_BYTES:
        raise InputError(f"{path}: larger than {YAML_LIMIT_BYTES // 2**20} MiB; not read")
    try:
        with open(path, encoding="utf-8") as f:
            return yaml.safe_load(f)
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(f"{path}: not a readable YAML file ({first})") from None


def _vector(path: Path, where: str, m: dict, key: str, n: int) -> list[float]:
    v = m.get(key) if isinstance(m, dict) else None
    if not isinstance(v, list | tuple) or len(v) != n:
        raise InputError(f"{path}: {where}: '{key}' must be a list of {n} numbers")
    out = []
    for x in v:
        if isinstance(x, bool) or not isinstance(x, int | float) or not math.isfinite(float(x)):
            raise InputError(f"{path}: {where}: '{key}' holds {x!r}, not a finite number")
        out.append(float(x))
    return out


def read_stationing_yaml(path: str | PathLike, chain: Chain, fiducials: str = "stationing") -> MeasurementSet:
    """The stationing file `path` as a measurement set with stations (module docstring).

    Parameters
    ----------
    path : str or PathLike
        The YAML file.
    chain : models.chain.Chain
        The robot's chain from its base link to the measured point (the prism), e.g.
        ``models.urdf.load_urdf(urdf, tip="prism")``; its joint columns must be the file's `joint_names`.
    fiducials : {"stationing", "half", "half-swapped"}
        Which points are fiducials (module docstring).

    Returns
    -------
    MeasurementSet
        Rows in file order per station; sensor (R, 3) instrument frame, robot (R, 3) the chain's base frame, mm;
        time s; extra columns: the joint columns and `group`.

    Raises
    ------
    InputError
        Unreadable or oversized file, a missing or malformed field (named with its station and measurement), joint
        names other than the chain's, or no station with stationing measurements.
    """
    if fiducials not in FIDUCIAL_CHOICES:
        raise InputError(f"fiducials {fiducials!r}: choose one of {', '.join(FIDUCIAL_CHOICES)}")
    p = Path(path)
    data = _load(p)
    if not isinstance(data, dict) or "joint_names" not in data or "column_heights" not in data:
        raise InputError(f"{p}: not a stationing file (it needs 'joint_names' and 'column_heights')")
    names = data["joint_names"]
    if not isinstance(names, list) or tuple(str(n) for n in names) != chain.columns:
        raise InputError(
            f"{p}: joint_names {names!r} are not the joints of {chain.name} from {chain.base} to {chain.tip} "
            f"({', '.join(chain.columns)}); give the robot's URDF and the measured link (--tip)"
        )
    heights = data["column_heights"]
    if not isinstance(heights, dict):
        raise InputError(f"{p}: 'column_heights' must map each height to its solution spaces")
    rows: list[tuple[str, str, str, list[float], list[float], float]] = []
    skipped = 0
    for h, hd in heights.items():
        spaces = hd.get("solution_spaces") if isinstance(hd, dict) else None
        if not isinstance(spaces, dict):
            raise InputError(f"{p}: height {h}: 'solution_spaces' must map each space to its measurements")
        for s, sd in spaces.items():
            station = f"h{h}_s{s}"
            if not isinstance(sd, dict):
                raise InputError(f"{p}: station {station}: not a mapping of measurement lists")
            st = sd.get("stationing_measurements") or []
            ev = sd.get("evaluation_measurements") or []
            if not isinstance(st, list) or not isinstance(ev, list):
                raise InputError(f"{p}: station {station}: the measurements must be lists")
            if not st:
                skipped += 1
                continue
            for kind, prefix, items in (("stationing", "S", st), ("evaluation", "E", ev)):
                for k, m in enumerate(items):
                    where = f"station {station}, {kind} measurement {k + 1}"
                    if not isinstance(m, dict) or "id" not in m:
                        raise InputError(f"{p}: {where}: needs an 'id'")
                    q = _vector(p, where, m, "joint_states", len(names))
                    prism = _vector(p, where, m, "prism_position", 3)
                    t = m.get("time", math.nan)
                    t = float(t) if isinstance(t, int | float) and not isinstance(t, bool) else math.nan
                    if kind == "stationing":
                        role = "both"
                    elif fiducials != "stationing" and k % 2 == (0 if fiducials == "half" else 1):
                        role = "fiducial"
                    else:
                        role = "check"
                    rows.append((f"{prefix}{m['id']}", role, station, q, prism, t))
    if not rows:
        raise InputError(f"{p}: no station has stationing measurements ({skipped} stations without)")
    q_all = np.array([r[3] for r in rows], float)
    scale = np.array([inp.scale for inp in chain.inputs], float)
    robot = chain.forward(q_all * scale)
    sensor = 1000.0 * np.array([r[4] for r in rows], float)
    extra: dict[str, tuple[str, ...]] = {
        inp.column: tuple(repr(float(v)) for v in q_all[:, i]) for i, inp in enumerate(chain.inputs)
    }
    extra[GROUP_COLUMN] = tuple(r[2] for r in rows)
    return MeasurementSet(
        ids=tuple(r[0] for r in rows),
        roles=tuple(r[1] for r in rows),
        sensor=sensor,
        robot=robot,
        time=np.array([r[5] for r in rows], float),
        lines=tuple(0 for _ in rows),
        source=p.name,
        extra=extra,
    )
