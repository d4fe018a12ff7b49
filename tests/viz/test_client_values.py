"""A client cannot break the shared session (issue 16, item 2): values a client sends are clamped on the server
(viser does not clamp them), the core refuses out-of-range settings, and any failure of an update rolls back."""

import math

import pytest

from rrbc_core.errors import InputError
from rrbc_core.session import figures
from rrbc_core.session.evaluation import SCALE_MAX, Settings


def _send(handle, value):
    """What viser does with a value a client sends: assign it (no clamping) and run the callbacks."""
    handle.value = value  # python-side assignment runs on_update too


@pytest.mark.parametrize("value, expected", [(1e308, 3.0), (-5.0, 0.0), (math.nan, 0.0), (math.inf, 0.0)])
def test_a_slider_value_a_client_sends_is_clamped_on_the_server(app, value, expected):
    _send(app.controls.explore.noise, value)
    assert app.session.settings.noise_scale == expected
    # the session still works for everyone afterwards
    assert app.evaluate.handle_drag("targets", "H1", [401.0, -150.0, 15.0], "end") is not None


def test_trials_a_client_sends_are_bounded(app):
    _send(app.controls.montecarlo.mc_trials, 200000)
    assert app.state.mc_trials == 1000
    with pytest.raises(InputError, match="trials"):
        figures.monte_carlo(app.session, trials=200000)


@pytest.mark.parametrize("field", ["noise_scale", "bias_scale"])
def test_the_core_refuses_sizes_beyond_its_bounds(field):
    with pytest.raises(InputError, match=field):
        Settings(**{field: 1e308})
    Settings(**{field: SCALE_MAX})  # the bound itself is fine


def test_any_failure_of_an_update_rolls_the_session_back(app, monkeypatch):
    session = app.session
    before = session.settings

    def broken():
        raise OverflowError("planted")

    monkeypatch.setattr(session, "evaluate", broken)
    with pytest.raises(OverflowError):
        session.update(noise_scale=2.0)
    assert session.settings == before
    monkeypatch.undo()
    assert app.evaluate.change_settings(noise_scale=2.0) is not None and session.settings.noise_scale == 2.0
