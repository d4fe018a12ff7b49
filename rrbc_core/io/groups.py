"""Stations in one measurement file: the optional `group` column (issue 28).

Real files hold several stationings — the robot re-registered at each height and arm configuration. Rows with the
same `group` value form one station: its own registration, fiducials, corrections; its targets and checks belong to
it. Format: docs/formats/measurement-file.md, "Stations".
"""

from __future__ import annotations

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.io.measurements import GROUP_COLUMN, MeasurementSet, select_rows

__all__ = ["GROUP_COLUMN", "group_label", "group_names", "has_groups", "select_rows", "split_groups"]


def has_groups(mset: MeasurementSet) -> bool:
    """Whether the set has a `group` column."""
    return GROUP_COLUMN in mset.extra


def group_names(mset: MeasurementSet) -> tuple[str, ...]:
    """The distinct `group` values in order of first appearance (empty without the column)."""
    return tuple(dict.fromkeys(mset.extra.get(GROUP_COLUMN, ())))


def group_label(source: str, name: str) -> str:
    """How messages name a station: ``data.csv, group 'station3'``."""
    return f"{source}, group {name!r}"


def split_groups(mset: MeasurementSet) -> tuple[tuple[str, MeasurementSet], ...]:
    """The stations of a set: (group value, its rows as a set) in order of first appearance. Each station's set keeps
    the `group` column and is named ``file, group 'g'`` in messages. A set without the column is one station
    named ""."""
    if not has_groups(mset):
        return (("", mset),)
    values = mset.extra[GROUP_COLUMN]
    out = []
    for name in group_names(mset):
        rows = [i for i, v in enumerate(values) if v == name]
        out.append((name, select_rows(mset, rows, group_label(mset.source, name))))
    return tuple(out)


def station_index(mset: MeasurementSet, min_registration: int) -> tuple[tuple[str, ...], np.ndarray | None]:
    """The stations' names and each row's station index (R,), or ((), None) without a group column; a station
    without `min_registration` registration rows is refused naming it (the reader already checks this for files)."""
    if not has_groups(mset):
        return (), None
    names = group_names(mset)
    index = {g: k for k, g in enumerate(names)}
    gi = np.array([index[v] for v in mset.extra[GROUP_COLUMN]], int)
    reg = np.isin(np.array(mset.roles), ("registration", "both"))
    for k, g in enumerate(names):
        if np.sum(reg & (gi == k)) < min_registration:
            raise InputError(f"{mset.source}, group {g!r}: fewer than {min_registration} registration rows")
    return names, gi
