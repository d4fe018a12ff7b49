"""A new tab in three files (issue 35): a panel, a controller and one `tab_plugin.TabSpec` in the app's list. Here
the three are written in this test file, the app is built with the list extended, and the tab works end to end:
its panel is laid out in the tab bar, a press reaches its controller, the controller shows through its panel's verbs,
and the app calls its hooks when a source is installed, an evaluation shown, the display changed and the app
stopped. The shipped plug-in tabs (Diagnose, Model) are held to the same shape."""

from __future__ import annotations

import ast
import contextlib
import io
from collections.abc import Callable
from typing import Any, Protocol

import pytest
import viser

from rrbc_viz import sources
from rrbc_viz.app import RunningApp
from rrbc_viz.tab_plugin import TabController, TabSpec
from rrbc_viz.tabs import TABS
from tests.paths import ROOT
from tests.viz.helpers import _press


# ---- file 1: the panel (its widgets, and the protocol of what it asks of its controller)
class CounterActions(Protocol):
    def count(self, client: Any = None) -> int: ...


class CounterPanel:
    def __init__(self, gui, controller: Callable[[], CounterActions]):
        self._button = gui.add_button("Count the targets")
        self._text = gui.add_markdown("not counted")
        self._button.on_click(lambda event: controller().count(client=event.client))

    def show(self, markdown: str) -> None:
        self._text.content = markdown

    def text(self) -> str:
        return self._text.content


# ---- file 2: the controller (a TabController over the context and its own panel)
class CounterController(TabController[CounterPanel]):
    def __init__(self, ctx, panel: CounterPanel):
        super().__init__(ctx, panel)
        self.hooks: list[str] = []

    def count(self, client=None) -> int:
        with self.ctx.lock:
            n = len(self.ctx.session.last.targets.ids)
            self.panel.show(f"{n} targets")
        return n

    def installed(self) -> None:
        self.hooks.append("installed")
        self.panel.show("not counted")

    def evaluated(self, ev) -> None:
        self.hooks.append("evaluated")

    def display_changed(self) -> None:
        self.hooks.append("display_changed")

    def stop(self) -> None:
        self.hooks.append("stop")


# ---- file 3: one entry in the list
COUNTER = TabSpec("counter", "Counter", "NUMBERS", CounterPanel, CounterController)


def test_a_tab_added_by_a_spec_is_laid_out_reached_and_told():
    with contextlib.redirect_stdout(io.StringIO()):
        server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    app = RunningApp(server, sources.load_source(None, None), "127.0.0.1", tabs=(*TABS, COUNTER))
    try:
        tab = app.tabs["counter"]
        panel = app.controls.tabs["counter"]
        assert isinstance(tab, CounterController) and tab.panel is panel
        assert tab.hooks[:1] == ["installed"] and "evaluated" in tab.hooks  # the first source
        # the tab bar holds it after the shipped plug-in tabs
        labels = app.controls.tab_labels()
        assert "Counter" in labels and labels.index("Counter") > labels.index("Model"), labels
        _press(panel._button)
        n = len(app.session.last.targets.ids)
        assert n > 0 and panel.text() == f"{n} targets"
        tab.hooks.clear()
        assert app.evaluate.handle_drag("targets", "H1", [401.0, -150.0, 15.0], "end") is not None
        assert "evaluated" in tab.hooks
        app.evaluate.set_display(magnification=50.0)
        assert "display_changed" in tab.hooks
        tab.hooks.clear()
        app.install(sources.load_source(None, None))
        assert tab.hooks[0] == "installed" and panel.text() == "not counted"
        # the other tabs still work beside it; a caller gets a tab's controller typed (a wrong class is refused)
        from rrbc_viz.controllers.diagnose import DiagnoseController

        assert app.tab("diagnose", DiagnoseController).run() is not None
        with pytest.raises(TypeError, match="not a DiagnoseController"):
            app.tab("counter", DiagnoseController)
    finally:
        app.stop()
    assert tab.hooks[-1] == "stop"


def test_the_shipped_plugin_tabs_have_the_three_file_shape():
    """Each shipped plug-in tab: a panel class in a `*_panel` module that imports no controller and no app, a
    TabController subclass in `controllers/`, and nothing else naming it in the app's wiring (`app.py`, `context.py`,
    `actions.py` and `controls.py` do not mention the tab by name)."""
    wiring = {name: (ROOT / "rrbc_viz" / name).read_text() for name in ("app.py", "context.py", "actions.py")}
    wiring["controls.py"] = (ROOT / "rrbc_viz" / "controls.py").read_text()
    for spec in TABS:
        panel_mod = spec.panel.__module__
        assert panel_mod.endswith("_panel"), panel_mod
        assert spec.controller.__module__.startswith("rrbc_viz.controllers."), spec.controller.__module__
        assert issubclass(spec.controller, TabController)  # type: ignore[arg-type]
        tree = ast.parse((ROOT / (panel_mod.replace(".", "/") + ".py")).read_text())
        imported = {(n.module or "") for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)} | {
            a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names
        }
        assert not any("controllers" in m or m.endswith("app") for m in imported), (panel_mod, imported)
        for name, text in wiring.items():
            for word in (spec.panel.__name__, spec.controller.__name__):  # type: ignore[union-attr]
                assert word not in text, f"{name} names {word}: a plug-in tab is wired by tabs.TABS only"


def test_a_layer_is_named_and_labelled_in_one_place():
    """A new layer of the 3-D scene: its name and its View-tab label in `node_values` (the control panel reads both
    from there), its nodes in a scene class, what it draws in `picture.ScenePicture`."""
    from rrbc_viz.node_values import LAYER_LABELS, LAYERS

    assert list(LAYER_LABELS) == list(LAYERS)
    assert "LAYER_LABELS = " not in (ROOT / "rrbc_viz" / "controls.py").read_text()
