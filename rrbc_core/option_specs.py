"""The options of a method, stated once: on the fields of its frozen option object.

A registration strategy (`registration.LeastSquares`, …) or an interpolation method (`interpolation.IDW`, …) is a
small frozen dataclass whose fields are its options. Each field made with `option(...)` carries an `OptionSpec` —
the command-line flag, the app's label, the valid bounds or choices, the range of the app's slider and a help
line — and everything that offers the option derives from it: `rrbc correct`'s flags (`cli.py`), the app's method
widgets (`rrbc_viz.controls`), the session's settings (`session.evaluation.Settings`) and validation
(`check_options`). A new option is one field; nothing else is written by hand.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rrbc_core.errors import InputError

__all__ = ["OptionSpec", "check_options", "option", "option_specs"]

_KEY = "rrbc_option"


@dataclass(frozen=True)
class OptionSpec:
    """One option of a method.

    Attributes
    ----------
    name : str
        The field's name on the option object.
    flag : str
        The command-line flag without dashes, and the name the session's settings use (e.g. "neighbors" for
        `IDW.k`); shared by options of different methods that mean the same (``average``).
    label : str
        The app's label for the option's widget.
    kind : type
        int, float or str.
    default : Any
        The field's default (None: "estimated" or "not set", when `nullable`).
    bounds : (lo, hi) or None
        Inclusive valid range of a number (`lo_open`: lo itself excluded).
    ui : (lo, hi, step) or None
        The app slider's range and step (inside `bounds`); None: not offered as a slider.
    choices : tuple or None
        The valid values of a str option (a dropdown in the app).
    help : str
        One line for `--help` and the widget's hint.
    nullable : bool
        None is a valid value.
    lo_open : bool
        The lower bound is excluded (a value must exceed it).
    """

    name: str
    flag: str
    label: str
    kind: type
    default: Any
    bounds: tuple | None = None
    ui: tuple | None = None
    choices: tuple | None = None
    help: str = ""
    nullable: bool = False
    lo_open: bool = False

    def check(self, value: Any, owner: str) -> Any:
        """`value` converted to `kind` and checked against the bounds or choices; InputError names the option."""
        what = f"{owner} {self.flag}"
        if value is None:
            if self.nullable:
                return None
            raise InputError(f"{what} must be given")
        if self.kind is str:
            text = str(value)
            if self.choices is not None and text not in self.choices:
                raise InputError(f"{what} must be one of {', '.join(self.choices)}, got {value!r}")
            return text
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise InputError(f"{what} must be a number, got {value!r}")
        x = float(value)
        if not math.isfinite(x):
            raise InputError(f"{what} must be finite, got {value!r}")
        v: int | float = x
        if self.kind is int:
            if x != int(x):
                raise InputError(f"{what} must be a whole number, got {value!r}")
            v = int(x)
        if self.bounds is not None:
            lo, hi = self.bounds
            if v < lo or v > hi or (self.lo_open and v == lo):
                raise InputError(
                    f"{what} must be {'above' if self.lo_open else 'from'} {lo:g} {'and at most' if self.lo_open else 'to'} {hi:g}, got {value!r}"
                )
        return v


def option(
    default: Any,
    *,
    label: str,
    help: str,
    flag: str | None = None,
    bounds: tuple | None = None,
    ui: tuple | None = None,
    choices: tuple | None = None,
    kind: type | None = None,
    lo_open: bool = False,
):
    """A dataclass field that is a method option (module docstring). `flag` defaults to the field's name."""
    spec = {
        "label": label,
        "help": help,
        "flag": flag,
        "bounds": bounds,
        "ui": ui,
        "choices": choices,
        "kind": kind,
        "lo_open": lo_open,
    }
    return field(default=default, metadata={_KEY: spec})


def option_specs(cls_or_obj) -> tuple[OptionSpec, ...]:
    """The `OptionSpec` of every option field of a method class (or object), in field order."""
    cls = cls_or_obj if isinstance(cls_or_obj, type) else type(cls_or_obj)
    out = []
    for f in dataclasses.fields(cls):
        meta = f.metadata.get(_KEY)
        if meta is None:
            continue
        default = f.default
        kind = meta["kind"] or (type(default) if default is not None else float)
        out.append(
            OptionSpec(
                name=f.name,
                flag=meta["flag"] or f.name,
                label=meta["label"],
                kind=kind,
                default=default,
                bounds=meta["bounds"],
                ui=meta["ui"],
                choices=meta["choices"],
                help=meta["help"],
                nullable=default is None,
                lo_open=meta["lo_open"],
            )
        )
    return tuple(out)


def check_options(obj, owner: str) -> None:
    """Check and normalise (int/float/str) every option field of a frozen option object in place (from its
    `__post_init__`). InputError names the method and the option's flag."""
    for spec in option_specs(obj):
        object.__setattr__(obj, spec.name, spec.check(getattr(obj, spec.name), owner))


def build_from_registry(registry: dict, name: str, options: dict, unknown_name: str, owner: str):
    """The option object registered under `name` (case and surrounding spaces ignored) built from `options` (None
    values: the defaults). InputError `unknown_name` for a name not in `registry`, and one naming the options the
    object does not take (`owner` names it: "method 'idw'", "registration 'three-point'")."""
    key = str(name).strip().lower()
    if key not in registry:
        raise InputError(unknown_name)
    cls = registry[key]
    given = {k: v for k, v in options.items() if v is not None}
    allowed = {spec.name for spec in option_specs(cls)}
    unknown = sorted(set(given) - allowed)
    if unknown:
        takes = ", ".join(sorted(allowed)) or "no options"
        raise InputError(
            f"{owner.format(key=repr(key))} does not take option(s) {', '.join(unknown)}; it takes: {takes}"
        )
    return cls(**given)
