"""The Model tab (`ModelCheckPanel`): hold the open scene's error model against a measurement file the app offers
(`rrbc check-model`): the file, the button, the command's own lines, *Extend the model* and the extended scene's
download. A plug-in tab (`tab_plugin`, listed in `tabs.TABS`): built inside its tab by `controls.Controls`, handed
a function returning its controller (`controllers.model_check.ModelCheckController`). Its markdown comes from
`render` (the command line's lines, escaped)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

import viser

from .diagnosis_panel import escape

if TYPE_CHECKING:
    from rrbc_core.analysis.scene_check import SceneCheck

NO_FILE = "(no measurement file offered)"
PROMPT = (
    "Holds the open scene's error model against one of **your** measurement files: the model is simulated at the "
    "file's own points, and the tab shows the measured FRE and check RMS beside their predicted 95 % ranges, which "
    "rows fall outside their own predicted region (dark red in the scene, with their misfit drawn), what the model "
    "leaves unexplained, and how much better the model extended by it predicts rows it was not fitted on. The same "
    "as `rrbc check-model DATA.csv SCENE.toml`. Files offered: .csv in scenes/ and in `rrbc view --data DIR`."
)
NOT_A_SCENE = "Open a scene first (File tab): the Model tab holds a scene's error model against a measurement file."


#: how the tab says where the rest is and how the extension is written (`scene_check_text.check_lines`' hints)
APP_HINTS = {
    "more": "dark red in the scene",
    "write": "**Extend the model** loads it, **Download extended scene** saves it",
}


def figures_table(res: SceneCheck) -> str:
    """The measured figures beside their predicted means and 95 % ranges, as a Markdown table (the panel is too
    narrow for the command's fixed-width lines)."""
    rows = ["| | measured | predicted | 95 % range | |", "| --- | ---: | ---: | --- | --- |"]
    for label, m, iv, out in res.figure_rows():
        if iv is None or m is None:
            rows.append(f"| {label} | - | - | no such rows | |")
            continue
        flag = "**OUTSIDE**" if out else "inside"
        rows.append(f"| {label} | {m:.4g} | {iv.mean:.4g} | {iv.lo95:.4g} – {iv.hi95:.4g} | {flag} |")
    return "\n".join(rows)


def render(res: SceneCheck, lines: list[str], head: str = "") -> str:
    """The tab's Markdown: the command's first line, the figures as a table (`figures_table`), then the command's
    other lines (`check_lines` with `APP_HINTS`), each a paragraph."""
    table_end = next((i for i, line in enumerate(lines) if line.startswith("rows outside")), 1)
    body = [escape(lines[0]), figures_table(res)] if lines else []
    body += [escape(line) for line in lines[table_end:]]
    return "\n\n".join(([head] if head else []) + body)


class ModelCheckTabActions(Protocol):
    """What the Model tab asks of its controller."""

    def run(self, label: str, client: Any = None, head: str = "") -> SceneCheck | None: ...
    def extend(self, client: Any = None) -> SceneCheck | None: ...
    def download(self, client: Any = None) -> tuple[str, bytes] | None: ...


class ModelCheckPanel:
    """Model tab (module docstring). `controller` returns the tab's controller (built after the panel)."""

    def __init__(self, gui, controller: Callable[[], ModelCheckTabActions]):
        self._file = gui.add_dropdown(
            "Measurement file", (NO_FILE,), initial_value=NO_FILE, hint="A .csv the app offers (scenes/, --data)"
        )
        self._check = gui.add_button("Check the scene's model", icon=viser.Icon.CHECKLIST)
        self._extend = gui.add_button(
            "Extend the model",
            icon=viser.Icon.PLUS,
            disabled=True,
            hint="Load the scene with the unexplained effects added as error terms, and check it again",
        )
        self._download = gui.add_button("Download extended scene (TOML)", icon=viser.Icon.DOWNLOAD, disabled=True)
        self._text = gui.add_markdown(PROMPT)
        self._check.on_click(lambda event: controller().run(self._file.value, client=event.client))
        self._extend.on_click(lambda event: controller().extend(client=event.client))
        self._download.on_click(lambda event: controller().download(client=event.client))

    def offer(self, files: list[str]) -> None:
        """The measurement files the tab offers (labels)."""
        self._file.options = tuple(files) or (NO_FILE,)
        if self._file.value not in self._file.options:
            self._file.value = self._file.options[0]

    def choose(self, label: str) -> None:
        """Select a file (tests, and the check run again after extending)."""
        self._file.value = label

    def show(self, markdown: str, extendable: bool = False, downloadable: bool | None = None) -> None:
        """The check's lines (`render`), or a prompt; whether *Extend* and the download apply (the download: by
        default when *Extend* does)."""
        self._text.content = markdown
        self._extend.disabled = not extendable
        self._download.disabled = not (extendable if downloadable is None else downloadable)

    def text(self) -> str:
        """What the tab shows (tests)."""
        return self._text.content
