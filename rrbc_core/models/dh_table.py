"""DH parameters as error terms and scene files write them: "UR5" or a table of a, d, alpha, theta_offset and
tool_mm (the rest from UR5), for the `kinematic` and `compliance` terms."""

from __future__ import annotations

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.models.errormodels import _number, _vector
from rrbc_core.models.kinematics import UR5, DHParameters

_DH_KEYS = ("a", "d", "alpha", "theta_offset", "tool_mm")


def _dh_value(value) -> DHParameters:
    """DH parameters from a DHParameters, the string "UR5", or a table with any of a, d (mm), alpha,
    theta_offset (rad; 6 values each) and tool_mm (mm); entries not given take the nominal UR5 values."""
    if isinstance(value, DHParameters):
        return value
    if isinstance(value, str) and value.upper() == "UR5":
        return UR5
    if isinstance(value, dict):
        unknown = sorted(set(value) - set(_DH_KEYS))
        if unknown:
            raise InputError(f"dh: unknown key {unknown[0]!r}; valid keys: {', '.join(_DH_KEYS)}")
        vals = {k: np.array(_vector(f"dh.{k}", value[k], 6)) if k in value else getattr(UR5, k) for k in _DH_KEYS[:4]}
        tool = _number("dh.tool_mm", value.get("tool_mm", UR5.tool_mm), unit="mm")
        return DHParameters(**vals, tool_mm=tool)
    raise InputError(
        f'dh must be "UR5" or a table with any of the keys {", ".join(_DH_KEYS)} (the rest from UR5); got {value!r}'
    )


def _dh_table(dh: DHParameters):
    """The shortest table form of `dh`: "UR5", {"tool_mm": …} for a UR5 with a tool, or every parameter."""
    if dh.same_as(UR5):
        return "UR5"
    if dh.same_as(UR5.with_tool(dh.tool_mm)):
        return {"tool_mm": dh.tool_mm}
    return dh.as_dict()
