"""Which ids (or other labels) belong to a set of them, in time linear in both.

numpy's `isin` compares arrays of Python objects (ids are strings of any length, kept as objects) pair by pair:
on a file of 100,000 fiducials that were also registration points, `rrbc correct` spent 219 s in it (issue 41,
measured by profiling the command once).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np


def member_of(values: Iterable, members: Iterable) -> np.ndarray:
    """(N,) bool: whether each of `values` (N labels: ids, station names) is one of `members` (any number)."""
    wanted = set(members)
    seq = values.tolist() if isinstance(values, np.ndarray) else list(values)
    return np.fromiter((v in wanted for v in seq), dtype=bool, count=len(seq))
