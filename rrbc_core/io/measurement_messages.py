"""The measurement reader's one-line messages (`io.measurements`): `<file>: line <n>: field <name>: <what is wrong>`,
the parts that do not apply left out, and the message for registration points that coincide or lie on a line."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.geometry.points import COINCIDENT_MM, COLLINEAR_RATIO, spread_ratios

#: at most this many ids are listed in a message
MAX_LISTED = 8


def message(source: str, line: int | None, fieldname: str | None, text: str) -> str:
    parts = [str(source)]
    if line:
        parts.append(f"line {line}")
    if fieldname:
        parts.append(f"field {fieldname}")
    parts.append(text)
    msg = ": ".join(parts)
    # One line, always: anything user-supplied is shown with repr(), but be safe about the rest.
    return msg.replace("\r", "\\r").replace("\n", "\\n")


def error(source: str, line: int | None, fieldname: str | None, text: str) -> InputError:
    return InputError(message(source, line, fieldname, text))


def listed(names: Sequence[str]) -> str:
    shown = ", ".join(repr(n) for n in names[:MAX_LISTED])
    if len(names) > MAX_LISTED:
        shown += f", ... ({len(names)} in all)"
    return shown


def registration_error(source, frame, reg, pts, last_line, exc) -> InputError:
    """The one-line message for registration points that do not determine a rotation in `frame`: two that coincide
    (naming them and their lines), all on (nearly) one line, or else the geometry check's own words (`exc`).
    `reg`: the registration points (`io.measurements.PointGroup`: ids, first lines), `pts` (N, 3) in that frame."""
    fieldname = f"{frame}_x/y/z"
    d = np.linalg.norm(pts[:, None, :] - pts[None, :, :], axis=-1)
    i, j = np.triu_indices(len(pts), k=1)
    close = d[i, j] < COINCIDENT_MM
    if np.any(close):
        a, b = int(i[close][0]), int(j[close][0])
        la, lb = reg.first_line[a], reg.first_line[b]
        where_a = f" (line {la})" if la else ""
        where_b = f" (line {lb})" if lb else ""
        return error(
            source,
            lb or last_line,
            fieldname,
            f"registration points {reg.ids[b]!r}{where_b} and {reg.ids[a]!r}{where_a} coincide in the {frame} frame "
            f"(closer than {COINCIDENT_MM} mm); use distinct, well-spread registration points",
        )
    r2, _ = spread_ratios(pts)
    if r2 < COLLINEAR_RATIO:
        return error(
            source,
            last_line,
            fieldname,
            f"registration points {listed(reg.ids)} are collinear or nearly so in the {frame} frame "
            f"(spread ratio sigma2/sigma1 = {r2:.2g} < {COLLINEAR_RATIO}): the rotation about their line is "
            "undetermined; add a registration point off that line",
        )
    text = str(exc).replace("\n", " ")
    return error(source, last_line, fieldname, text)
