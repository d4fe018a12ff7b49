"""The app's house rules (issue 35, item 1), checked on the source: one typed state object owns what is shown,
controllers change it, views render it behind verbs. No controller (nor the app that wires them) reads a view's
state or reaches into its handles: every use of a view (the scene's nodes, the slice, the camera director, the
control panel and the Plan tab's panel) is a method call."""

from __future__ import annotations

import ast

import pytest

from tests.paths import ROOT

#: the views as the controllers reach them through the context (`context.AppContext`)
VIEWS = {"nodes", "slice_node", "check_node", "camera", "controls", "planning"}
#: the control panel's tabs and folders (each a panel class with its own verbs)
PANELS = {
    "selection",
    "explore",
    "checks",
    "view",
    "learn",
    "montecarlo",
    "vec",
    "file",
    "authoring",
}
CONTROLLERS = sorted((ROOT / "rrbc_viz" / "controllers").glob("*.py")) + [ROOT / "rrbc_viz" / "app.py"]


def _view_uses(tree: ast.AST) -> list[tuple[int, str]]:
    """(line, source) of every use of a view that is not a method call: `ctx.nodes.x` read or written,
    `ctx.controls.explore.widget.value`, a view handed around as a value. A view bound to a local name
    (`c = self.ctx.controls`) is followed; a property of the app returning a view (for tests and scripts) is not a
    use."""
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}

    def called(node: ast.AST) -> bool:
        parent = parents.get(node)
        return isinstance(parent, ast.Call) and parent.func is node

    def view_of(node: ast.AST) -> str | None:
        if isinstance(node, ast.Attribute) and node.attr == "panel":  # a plug-in tab's own panel (tab_plugin)
            if isinstance(node.value, ast.Name) and node.value.id == "self":
                return "panel"
        if isinstance(node, ast.Attribute) and node.attr in VIEWS:
            base = node.value  # ctx, self.ctx, self._ctx
            if (isinstance(base, ast.Name) and base.id in ("ctx", "context")) or (
                isinstance(base, ast.Attribute) and base.attr in ("ctx", "_ctx")
            ):
                return node.attr
        return None

    aliases = {
        n.targets[0].id: view_of(n.value)
        for n in ast.walk(tree)
        if isinstance(n, ast.Assign) and len(n.targets) == 1 and isinstance(n.targets[0], ast.Name) and view_of(n.value)
    }
    bad = []
    for node in ast.walk(tree):
        view = view_of(node) or (aliases.get(node.id) if isinstance(node, ast.Name) else None)
        if view is None:
            continue
        use = parents.get(node)
        if isinstance(use, ast.Assign) and isinstance(node, ast.Attribute) and use.value is node:
            if len(use.targets) == 1 and isinstance(use.targets[0], ast.Name):
                continue  # bound to a local name: its uses are checked
        if isinstance(use, ast.Return) and isinstance(node, ast.Attribute):
            continue  # the app's property (tests and scripts look at the views)
        if isinstance(node, ast.Name) and isinstance(use, ast.Assign) and node in use.targets:
            continue  # the alias being bound
        if isinstance(use, ast.Attribute) and called(use):
            continue  # ctx.nodes.show(picture)
        if (
            view == "controls"
            and isinstance(use, ast.Attribute)
            and use.attr in PANELS
            and isinstance(parents.get(use), ast.Attribute)
            and called(parents[use])
        ):
            continue  # ctx.controls.explore.show_results(...)
        bad.append((node.lineno, ast.unparse(use if isinstance(use, ast.Attribute) else node)))
    return bad


@pytest.mark.parametrize("path", CONTROLLERS, ids=lambda p: p.name)
def test_no_controller_reads_a_views_state(path):
    bad = _view_uses(ast.parse(path.read_text()))
    assert not bad, f"{path.relative_to(ROOT)}: views used other than by a verb: {bad}"


def test_the_check_sees_reads_writes_and_reaching_into_a_panel():
    """The rule above can fail: reads, writes and widget values through the context are found; verbs are not."""
    code = (
        "def f(self, ctx):\n"
        "    a = self.ctx.nodes.landing\n"  # a read
        "    ctx.nodes.target_arrows = True\n"  # a write
        "    n = self.ctx.controls.montecarlo.mc_trials.value\n"  # a widget's value
        "    g(ctx.planning)\n"  # the view handed around
        "    self.ctx.nodes.show(picture)\n"  # verbs: fine
        "    ctx.controls.explore.show_results(1, 2, 3)\n"
        "    ctx.controls.show_status('x')\n"
        "    c = self.ctx.controls\n"  # an alias: its uses are checked
        "    c.explore.show_results(1, 2, 3)\n"
        "    k = c.plan.k\n"  # a read through the alias
        "    return self.ctx.nodes\n"  # the app's property
        "    self.panel.show('x')\n"  # a plug-in tab's own panel: a verb
        "    t = self.panel._text.content\n"  # and a read
    )
    lines = sorted(line for line, _ in _view_uses(ast.parse(code)))
    assert lines == [2, 3, 4, 5, 11, 14], lines


def test_the_state_is_the_one_owner_of_what_the_scene_shows():
    """The scene's nodes keep no public fields: what they show comes in through verbs (`show(picture)`, `set_*`),
    and what the app shows lives in `state.AppState`, which the presenting function reads."""
    from rrbc_viz.nodes import SceneNodes

    init = next(
        n
        for n in ast.walk(ast.parse((ROOT / "rrbc_viz" / "nodes.py").read_text()))
        if isinstance(n, ast.FunctionDef) and n.name == "__init__"
    )
    public = [
        t.attr
        for n in ast.walk(init)
        if isinstance(n, (ast.Assign, ast.AnnAssign))
        for t in (n.targets if isinstance(n, ast.Assign) else [n.target])
        if isinstance(t, ast.Attribute) and not t.attr.startswith("_")
    ]
    assert public == [], public
    assert callable(SceneNodes.show) and callable(SceneNodes.build)
