"""Writing a scene extended by `rrbc check-model` (docs/check_model.md): the scene file's own text, unchanged, with
the added error terms appended as `[[error_model.robot]]` tables, each under a comment saying where it came from.
The text is read back by `scene_toml.load_scene` (from a temporary file beside the output, so the mesh path is
resolved as it will be) before the file is written, atomically."""

from __future__ import annotations

import os
import secrets
from collections.abc import Sequence
from pathlib import Path

from rrbc_core.errors import InputError
from rrbc_core.io.measurements_write import atomic_write_text, output_path
from rrbc_core.io.scene_write import _value

__all__ = ["check_destination", "extended_scene_text", "write_extended_scene"]


def extended_scene_text(scene_text: str, terms: Sequence[tuple[dict, str]], header: str) -> str:
    """The scene's text with `terms` ((table, comment) pairs, robot side) appended under the comment `header`."""
    text = scene_text.lstrip("\ufeff")
    lines = [text.rstrip("\n"), "", f"# --- {header} ---"]
    for table, comment in terms:
        lines.append(f"# {comment}")
        lines.append("[[error_model.robot]]")
        for key, value in table.items():
            lines.append(f"{key} = {_value(value)}")
        lines.append("")
    return "\n".join(lines).rstrip("\n") + "\n"


def check_destination(scene_path: str | os.PathLike, out: str | os.PathLike, text: str) -> str:
    """That scene text `text` loads when placed at `out` (its mesh path resolved from there); returns the path to
    write. Call it with the scene's own text before long work, and with the extended text before writing.

    Raises
    ------
    InputError
        The output cannot be written, or the scene does not load from there (its mesh path is relative to the
        scene's folder: write it beside the scene).
    """
    from rrbc_core.io.scene_toml import load_scene

    dest = output_path(out)
    probe = Path(os.path.dirname(os.path.abspath(dest))) / f".{Path(dest).name}.{secrets.token_hex(6)}.toml"
    try:
        probe.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise InputError(f"{dest}: cannot write the file: {exc.strerror or exc}") from None
    try:
        load_scene(probe)
    except InputError as exc:
        where = os.path.dirname(os.path.abspath(os.fspath(scene_path)))
        raise InputError(
            f"{dest}: the extended scene would not load from there ({str(exc).split(': ', 1)[-1]}); "
            f"write it in the scene's folder {where}"
        ) from None
    finally:
        probe.unlink(missing_ok=True)
    return dest


def write_extended_scene(scene_path: str | os.PathLike, out: str | os.PathLike, text: str) -> None:
    """Validate `text` as a scene placed at `out` (`check_destination`) and write it there atomically."""
    atomic_write_text(check_destination(scene_path, out, text), text)
