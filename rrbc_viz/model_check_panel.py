"""The Model tab (`ModelCheckPanel`): hold the open scene's error model against a measurement file the app offers
(`rrbc check-model`): the file, the button, the command's own lines, *Extend the model* and the extended scene's
download. Built inside its tab by `controls.Controls`; handed the app as `actions.Actions`. Its markdown comes from
`render` (the command line's lines, escaped)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import viser

from .diagnosis_panel import escape

if TYPE_CHECKING:
    from .actions import Actions

NO_FILE = "(no measurement file offered)"
PROMPT = (
    "Holds the open scene's error model against one of **your** measurement files: the model is simulated at the "
    "file's own points, and the tab shows the measured FRE and check RMS beside their predicted 95 % ranges, which "
    "rows fall outside their own predicted region (dark red in the scene, with their misfit drawn), what the model "
    "leaves unexplained, and how much better the model extended by it predicts rows it was not fitted on. The same "
    "as `rrbc check-model DATA.csv SCENE.toml`. Files offered: .csv in scenes/ and in `rrbc view --data DIR`."
)
NOT_A_SCENE = "Open a scene first (File tab): the Model tab holds a scene's error model against a measurement file."


def render(lines: list[str], head: str = "") -> str:
    """The command's lines as Markdown: the figures' table in a code block, each other line a paragraph."""
    table_end = next((i for i, line in enumerate(lines) if line.startswith("rows outside")), 1)
    body = [escape(lines[0])] if lines else []
    if table_end > 1:
        body.append("```\n" + "\n".join(lines[1:table_end]) + "\n```")
    body += [escape(line) for line in lines[table_end:]]
    return "\n\n".join(([head] if head else []) + body)


class ModelCheckPanel:
    """Model tab (module docstring)."""

    def __init__(self, gui, app: Actions):
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
        self._check.on_click(lambda event: app.model_check.run(self._file.value, client=event.client))
        self._extend.on_click(lambda event: app.model_check.extend(client=event.client))
        self._download.on_click(lambda event: app.model_check.download(client=event.client))

    def offer(self, files: list[str]) -> None:
        """The measurement files the tab offers (labels)."""
        self._file.options = tuple(files) or (NO_FILE,)
        if self._file.value not in self._file.options:
            self._file.value = self._file.options[0]

    def choose(self, label: str) -> None:
        """Select a file (tests, and the check run again after extending)."""
        self._file.value = label

    def show(self, markdown: str, extendable: bool = False) -> None:
        """The check's lines (`render`), or a prompt; whether *Extend* and the download apply."""
        self._text.content = markdown
        self._extend.disabled = not extendable
        self._download.disabled = not extendable

    def text(self) -> str:
        """What the tab shows (tests)."""
        return self._text.content
