"""rrbc_viz: the browser app (viser 1.1.1) over `rrbc_core.session.explorer.ExplorerSession`.

Start it with `rrbc_viz.serve.serve(...)` (what `rrbc view` calls). The app is a composition (`app.RunningApp`): a
shared context (`context`, `state`), one controller per feature (`controllers/`) behind narrow interfaces
(`actions`), the scene views (`nodes`, `heatmap_nodes`, `slice_nodes`, `robot_nodes`) and the panels (`controls`
and the panels it builds). Every number it shows comes from the core (docs/architecture.md).
"""

__all__ = ["serve", "RunningApp"]


def __getattr__(name):  # lazy: importing rrbc_viz does not start viser
    if name == "serve":
        from .serve import serve

        return serve
    if name == "RunningApp":
        from .app import RunningApp

        return RunningApp
    raise AttributeError(name)
