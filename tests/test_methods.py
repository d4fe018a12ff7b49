"""One spelling of each method (issue 26, item 2): the strategies and interpolations are option objects; their
fields' specs are the only place an option's flag, bounds and help are written; the command line's flags, the
session's settings and the app's widgets are derived from them and agree."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from rrbc_core import interpolation, registration
from rrbc_core.cli import build_parser, main
from rrbc_core.errors import InputError
from rrbc_core.methods import MethodOptions, method_flags
from rrbc_core.option_specs import option_specs
from rrbc_core.session.evaluation import Settings
from tests.paths import EXAMPLE_CSV


def test_every_method_is_an_option_object_with_register_or_fit():
    pts = np.random.default_rng(0).normal(size=(8, 3)) * 100
    for name, cls in registration.STRATEGIES.items():
        obj = registration.make_strategy(name)
        assert type(obj) is cls and obj.name == name
        reg = obj.register(pts, pts + [1.0, 2.0, 3.0])
        assert reg.mapping.piecewise == (name == "clustering") and isinstance(reg.mapping, registration.SensorToRobot)
    for name, cls in interpolation.METHODS.items():
        assert interpolation.make_interpolator(name).name == name and hasattr(cls, "fit")


def test_the_command_line_offers_every_option_with_its_specs_bounds(capsys):
    actions = {a.dest: a for a in build_parser()._subparsers._group_actions[0].choices["correct"]._actions}
    for flag, owners in method_flags().items():
        dest = "seed" if flag == "seed" else "opt_" + flag.replace("-", "_")
        assert dest in actions, flag
        spec = owners[0][2]
        if spec.choices:
            assert tuple(actions[dest].choices) == spec.choices
    for args, ok in ((["--registration", "clustering", "--clusters", "3"], True), (["--clusters", "3"], False)):
        rc = main(["correct", str(EXAMPLE_CSV), *args, "--json"])
        out, err = capsys.readouterr()
        assert (rc == 0) == ok, err
        if ok:
            assert json.loads(out)["registration"]["clusters"] == 3
        else:
            assert "--clusters applies to clustering only" in err
    assert main(["correct", str(EXAMPLE_CSV), "--clusters", "51", "--registration", "clustering"]) == 2
    assert "clusters must be from 1 to 50" in capsys.readouterr().err


def test_settings_route_options_by_flag_and_keep_those_of_methods_not_chosen():
    s = Settings(interpolation="idw", neighbors=6, smoothing=0.2)
    assert s.method.interpolation == interpolation.IDW(k=6) and s.neighbors == 6 and s.smoothing == 0.2
    t = s.replace(interpolation="tps")
    assert t.method.interpolation == interpolation.TPS(smoothing=0.2) and t.neighbors == 6
    c = Settings(registration="combinatorial", average="chordal")
    assert c.method.registration == registration.Combinatorial(average="chordal")
    k = Settings(registration="clustering", clusters=3, seed=7)
    assert k.method.registration == registration.Clustering(clusters=3, seed=7)
    for bad in ({"neighbors": 0}, {"power": 0.0}, {"clusters": 100}, {"average": "median"}, {"wobble": 1}):
        with pytest.raises(InputError):
            Settings(**bad)
    assert MethodOptions.named("least-squares", "tps", smoothing=0.1) == MethodOptions(
        registration.LeastSquares(), interpolation.TPS(0.1)
    )


def test_specs_are_the_only_bounds():
    """No method module states an option's bound outside its field's spec: the specs exist for every option field."""
    for registry in (registration.STRATEGIES, interpolation.METHODS):
        for cls in registry.values():
            names = {s.name for s in option_specs(cls)}
            fields = {f.name for f in dataclasses.fields(cls)}  # instance fields (ClassVars excluded)
            assert fields == names, (cls, fields, names)


def test_methods_sharing_a_flag_declare_the_same_spec():
    """One flag is one CLI option and one app widget, validated and drawn from the first owner's spec: every method
    that offers the same flag must declare it identically (only the field's name may differ), or the other owners'
    bounds, choices and defaults would be silently ignored."""

    by_flag: dict[str, list] = {}
    for registry in (registration.STRATEGIES, interpolation.METHODS):
        for key, cls in registry.items():
            for spec in option_specs(cls):
                by_flag.setdefault(spec.flag, []).append((key, dataclasses.replace(spec, name="")))
    shared = {flag: owners for flag, owners in by_flag.items() if len(owners) > 1}
    assert shared, "no flag is shared: this test would check nothing"
    for flag, owners in shared.items():
        first_key, first = owners[0]
        for key, spec in owners[1:]:
            assert spec == first, f"--{flag}: {key} declares {spec}, {first_key} declares {first}"
