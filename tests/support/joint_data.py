"""Simulated measurement files WITH joint angles for the calibration tests, written to disk: the library's own
simulator (rrbc_core.studies.vec_study.joint_measurements, physics in its docstring) and the file writer."""

from __future__ import annotations

from pathlib import Path

from rrbc_core.io.measurements_write import write_measurements
from rrbc_core.studies.vec_study import joint_measurements


def joint_file(path: Path, seed: int, **kwargs) -> Path:
    write_measurements(path, joint_measurements(seed, source=str(path), **kwargs))
    return path
