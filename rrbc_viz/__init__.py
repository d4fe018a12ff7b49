"""rrbc_viz: the browser app (viser) over `rrbc_core.explorer.ExplorerSession`.

Modules: `app` (serve, RunningApp: server, wiring, drag handling), `nodes` (3-D scene nodes), `controls` (the
control panel), `teaching` (the nine-step lesson), `tables` (markdown results), `colors` (palette, heat-map
scale), `files` (opening sources, exporting CSV), `montecarlo` (background Monte Carlo), `diagnosis_panel` (the
Diagnose tab), `planning_panel` (the Plan tab: coverage, predicted RMST, suggested fiducials), `worker` (the
coalescing background worker both use).
The app is a thin layer: every number it shows comes from the core session.
"""

__all__ = ["serve", "RunningApp"]


def __getattr__(name):  # lazy: importing rrbc_viz does not start viser
    if name in __all__:
        from . import app

        return getattr(app, name)
    raise AttributeError(name)
