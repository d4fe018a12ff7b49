"""The Diagnose tab (`DiagnosePanel`, a plug-in tab: `tab_plugin`) and its Markdown: which data it diagnosed and,
unchanged, the lines `rrbc diagnose` prints.

Every word of the verdict comes from `rrbc_core.analysis.diagnosis_text.diagnosis_lines` (the command line's own
text), escaped for Markdown; this module adds only the heading (which data, the equivalent command).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any, Protocol

import viser

from rrbc_core.analysis.diagnosis import Diagnosis
from rrbc_core.analysis.diagnosis_text import diagnosis_lines
from rrbc_core.session.data_set import SessionData

PROMPT = (
    "Tests the session's data — the file as opened (or as you edited it), or for a scene the simulated data set "
    "that **Download data (CSV)** writes — for what a rigid fit with isotropic noise misses: outliers, scale, "
    "affine terms, drift, the arm's kinematic error (joint columns), a smooth field, anisotropic noise; and whether "
    "RRBC helps. It shows exactly what `rrbc diagnose` prints for those data. Press **Diagnose current data**."
)
STALE = "**(data changed since — press again)**"
_SPECIAL = re.compile(r"([\\`*_{}\[\]<>()#+\-.!|~])")


def escape(text: str) -> str:
    """Markdown-escaped `text`: shown as written (the command line's words, character for character)."""
    return _SPECIAL.sub(r"\\\1", text)


def unescape(markdown: str) -> str:
    """The text of `escape(text)` (tests compare the tab with the command line through it)."""
    return re.sub(r"\\(.)", r"\1", markdown)


def render(d: Diagnosis, data: SessionData, stale: bool = False) -> str:
    """The tab's content: which data were diagnosed (edited or not), the command that prints the same, then
    `diagnosis_lines(d)` one paragraph each, escaped."""
    head = [STALE] if stale else []
    note = "**Edited data.** " if data.edited else ""
    head.append(
        f"{note}Diagnosis of {escape(data.what)}. The same as `{data.diagnose_command('DATA.csv')}` on "
        "these data (**File → Download data (CSV)** writes them)."
    )
    lines = diagnosis_lines(d)
    table = d.check_statistics.lines() if d.check_statistics is not None else []
    at = next((i for i in range(len(lines)) if lines[i : i + len(table)] == table), None) if table else None
    body = [escape(line) for line in lines]
    if at is not None:  # the before/after table as the command prints it, its columns kept
        body[at : at + len(table)] = ["```\n" + "\n".join(table) + "\n```"]
    return "\n\n".join(head + body)


def render_error(message: str, stale: bool = False) -> str:
    return ((STALE + "\n\n") if stale else "") + f"⚠ Cannot diagnose: {' '.join(str(message).split())}"


class DiagnoseTabActions(Protocol):
    """What the Diagnose tab asks of its controller (`controllers.diagnose.DiagnoseController`)."""

    def run(self, client: Any = None) -> Diagnosis | None: ...


class DiagnosePanel:
    """Diagnose tab: the button and the verdict. `controller` returns the tab's controller (built after the panel)."""

    def __init__(self, gui, controller: Callable[[], DiagnoseTabActions]):
        self.diagnose = gui.add_button(
            "Diagnose current data",
            icon=viser.Icon.STETHOSCOPE,
            hint="Test the registration points and fiducials (not the targets) for effects a rigid fit misses",
        )
        self.diagnosis = gui.add_markdown(PROMPT)
        self.diagnose.on_click(lambda event: controller().run(client=event.client))

    def show(self, markdown: str) -> None:
        """The verdict (`render`), an error, or the verdict marked stale."""
        self.diagnosis.content = markdown

    def show_prompt(self) -> None:
        self.diagnosis.content = PROMPT
