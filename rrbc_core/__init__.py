"""rrbc_core: Restoration of Rigid-Body Condition (RRBC) — registration, corrections, simulation, analysis.

A headless numpy/scipy library (the browser app, `rrbc_viz`, is a layer on top of it). One convention everywhere:
robot = R @ sensor + t, points as rows, millimetres. Bad input raises `InputError` with a message a user can act on.

    import rrbc_core as rrbc

    data = rrbc.read_measurements("measurements.csv")
    result = rrbc.correct_measurements(data, rrbc.MethodOptions(interpolation="idw"))
    for pid, p in zip(result.targets.ids, result.targets_corrected.robot_rrbc):
        print(pid, p)                      # each target's corrected robot-frame position, mm

The layers (subpackages) and where things live: docs/architecture.md.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

#: Each public name and the module that defines it. Loaded on first use (PEP 562), so `import rrbc_core` and the
#: `rrbc` command stay fast; `from rrbc_core import plan` works as usual.
_EXPORTS = {
    "InputError": "rrbc_core.errors",
    "RigidTransform": "rrbc_core.geometry.transforms",
    "MethodOptions": "rrbc_core.methods",
    "register": "rrbc_core.registration",
    "Registration": "rrbc_core.registration",
    "make_interpolator": "rrbc_core.interpolation",
    "hull_flags": "rrbc_core.interpolation",
    "read_measurements": "rrbc_core.io.measurements",
    "parse_measurements": "rrbc_core.io.measurements",
    "MeasurementSet": "rrbc_core.io.measurements",
    "write_measurements": "rrbc_core.io.measurements_write",
    "correct_measurements": "rrbc_core.correction.pipeline",
    "CorrectionResult": "rrbc_core.correction.pipeline",
    "load_scene": "rrbc_core.io.scene_toml",
    "default_scene_path": "rrbc_core.io.scene",
    "Scene": "rrbc_core.io.scene",
    "simulate": "rrbc_core.simulation.montecarlo",
    "simulated_data": "rrbc_core.simulation.datasets",
    "MonteCarloResult": "rrbc_core.simulation.montecarlo",
    "diagnose": "rrbc_core.analysis.diagnosis",
    "Diagnosis": "rrbc_core.analysis.diagnosis",
    "plan": "rrbc_core.analysis.planning",
    "predict_rmst": "rrbc_core.analysis.planning",
    "coverage": "rrbc_core.analysis.planning",
    "PlanResult": "rrbc_core.analysis.planning",
    "ExplorerSession": "rrbc_core.session.explorer",
}

if TYPE_CHECKING:  # what type checkers and editors see
    from rrbc_core.analysis.diagnosis import Diagnosis, diagnose
    from rrbc_core.analysis.planning import PlanResult, coverage, plan, predict_rmst
    from rrbc_core.correction.pipeline import CorrectionResult, correct_measurements
    from rrbc_core.errors import InputError
    from rrbc_core.geometry.transforms import RigidTransform
    from rrbc_core.interpolation import hull_flags, make_interpolator
    from rrbc_core.io.measurements import MeasurementSet, parse_measurements, read_measurements
    from rrbc_core.io.measurements_write import write_measurements
    from rrbc_core.io.scene import Scene, default_scene_path
    from rrbc_core.io.scene_toml import load_scene
    from rrbc_core.methods import MethodOptions
    from rrbc_core.registration import Registration, register
    from rrbc_core.session.explorer import ExplorerSession
    from rrbc_core.simulation.datasets import simulated_data
    from rrbc_core.simulation.montecarlo import MonteCarloResult, simulate


__version__: str  # the installed distribution's version, read on first use (importlib.metadata costs ~30 ms)


def _version() -> str:
    from importlib import metadata

    try:
        return metadata.version("rrbc")
    except metadata.PackageNotFoundError:  # a checkout on sys.path without installing
        return "0+unknown"


def __getattr__(name: str):
    if name == "__version__":
        globals()[name] = value = _version()
        return value
    if name in _EXPORTS:
        value = getattr(importlib.import_module(_EXPORTS[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'rrbc_core' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_EXPORTS) | {"__version__"})


__all__ = [
    "__version__",
    "InputError",
    "RigidTransform",
    "MethodOptions",
    "register",
    "Registration",
    "make_interpolator",
    "hull_flags",
    "read_measurements",
    "parse_measurements",
    "write_measurements",
    "MeasurementSet",
    "correct_measurements",
    "CorrectionResult",
    "load_scene",
    "default_scene_path",
    "Scene",
    "simulate",
    "simulated_data",
    "MonteCarloResult",
    "diagnose",
    "Diagnosis",
    "plan",
    "predict_rmst",
    "coverage",
    "PlanResult",
    "ExplorerSession",
]
