"""The selected point in the panel: a dropdown to pick it (besides clicking it in the scene), its info card, a
button to exclude or include a selected fiducial, and the landing bullseye (`selection_card`). The bullseye is
shown twice, in the Explore tab and in the Learn tab (step 9), from the same content."""

from __future__ import annotations

from typing import TYPE_CHECKING

import viser

from .selection_card import SORTS, parse_choice

if TYPE_CHECKING:
    from .actions import Actions
    from .syncing import Syncing


class Bullseye:
    """One bullseye: an HTML block (SVG and key) and its caption."""

    def __init__(self, gui):
        self.html = gui.add_html("", visible=False)
        self.caption = gui.add_markdown("", visible=False)

    def show(self, svg: str | None, caption: str = "", key: str = "") -> None:
        on = svg is not None
        if on:
            self.html.content = f'<div style="text-align:center">{svg}<div style="font-size:0.85em">{key}</div></div>'
            self.caption.content = caption
        self.html.visible = self.caption.visible = on


class SelectionPanel:
    """Explore tab, top: pick a point, its numbers, its bullseye."""

    def __init__(self, gui, app: Actions, syncing: Syncing):
        self.app, self.syncing = app, syncing
        with gui.add_folder("Selected point"):
            self.choice = gui.add_dropdown("Select", ("none",), initial_value="none")
            self.sort = gui.add_dropdown(
                "List by", SORTS, initial_value=SORTS[0], hint="order the points above: file order, or largest first"
            )
            self.info = gui.add_markdown("")
            self.exclude = gui.add_button("Exclude / include this fiducial", visible=False)
            self.bullseye = Bullseye(gui)

        @self.choice.on_update
        def _(event: viser.GuiEvent) -> None:
            if not self.syncing.on:
                sel = parse_choice(self.choice.value)
                if sel is None:
                    app.views.select(None, client=event.client)
                else:
                    app.views.select(sel[0], sel[1], client=event.client)

        @self.sort.on_update
        def _(event: viser.GuiEvent) -> None:
            if not self.syncing.on:
                app.views.set_point_sort(self.sort.value)

        @self.exclude.on_click
        def _(event: viser.GuiEvent) -> None:
            sel = parse_choice(self.choice.value)
            if sel is not None and sel[0] == "fiducials":
                app.evaluate.toggle_fiducial(sel[1], client=event.client)

    def show_card(self, markdown: str) -> None:
        """The selected point's card (`selection_card.info_card`)."""
        if self.info.content != markdown:
            self.info.content = markdown

    def sync(self, choices: tuple[str, ...], value: str, selected) -> None:
        with self.syncing.quiet():
            if tuple(self.choice.options) != tuple(choices):
                self.choice.options = choices
            self.choice.value = value
        self.exclude.visible = selected is not None and selected[0] == "fiducials"
