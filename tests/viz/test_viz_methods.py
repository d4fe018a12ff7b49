"""The app's method widgets are the option fields' specs (issue 26, item 2)."""

from rrbc_core import registration
from rrbc_core.methods import method_flags


def test_the_apps_widgets_are_the_specs(app):
    explore = app.controls.explore
    for flag, widget in explore.options.items():
        spec = method_flags()[flag][0][2]
        if spec.choices:
            assert tuple(widget.options) == spec.choices
        else:
            lo, hi, step = spec.ui
            assert (widget.min, widget.max, widget.step) == (lo, hi, step)
            assert spec.bounds[0] <= lo and hi <= spec.bounds[1]
    assert {"neighbors", "power", "smoothing", "clusters", "average", "kernel"} <= set(explore.options)
    # a registration option the app could not express before: clustering's clusters
    app.evaluate.change_settings(registration="clustering")
    assert explore.options["clusters"].visible and not explore.options["smoothing"].visible
    explore.options["clusters"].value = 3
    assert app.session.settings.method.registration == registration.Clustering(
        clusters=3, seed=app.session.settings.seed
    )
    assert app.session.last.registration.details["clusters"] == 3
