"""`rrbc diagnose` on a file with joint columns and no arm model tested: it says the sensor effects it names may be
the arm's, that a scale beyond a measuring instrument's is implausible, and how to give the model (issue 38: "the
sensor blamed for the arm")."""

from __future__ import annotations

import dataclasses

from rrbc_core.analysis.diagnosis import diagnose
from rrbc_core.analysis.diagnosis_arm import arm_untested_hint, joint_like_columns
from rrbc_core.analysis.diagnosis_systematic import Effect
from rrbc_core.studies.vec_study import TOOL_MM, joint_measurements


def _renamed(mset, names):
    """The file with its q1..q6 columns under other names (a robot whose model rrbc does not know)."""
    extra = {names.get(k, k): v for k, v in mset.extra.items()}
    return dataclasses.replace(mset, extra=extra)


def test_joint_columns_under_any_common_name_are_recognised():
    m = joint_measurements(1, n_fid=20, n_chk=10)
    assert joint_like_columns(m) == [f"q{i}" for i in range(1, 7)]
    for names in ({f"q{i}": f"joint_{i}" for i in range(1, 7)}, {f"q{i}": f"A{i}" for i in range(1, 7)}):
        assert joint_like_columns(_renamed(m, names)) == list(names.values())
    none = dataclasses.replace(m, extra={k: v for k, v in m.extra.items() if not k.startswith("q")})
    assert joint_like_columns(none) == []


def test_an_arm_error_seen_without_a_model_is_said_to_be_possibly_the_arms():
    """A UR5 with kinematic errors, its joint columns named joint_1..joint_6 (so the default UR5 test cannot read
    them): what diagnose names comes with the hint; with the model given the arm is tested and no hint is given."""
    m = joint_measurements(2, dh_size=3.0, n_fid=200, n_chk=60)
    res = diagnose(_renamed(m, {f"q{i}": f"joint_{i}" for i in range(1, 7)}), seed=0)
    named = {e.name for e in res.effects}
    assert named & {"scale", "affine", "smooth_field"}, named
    [hint] = [x for x in res.limits if "no arm model was tested" in x]
    assert "joint_1" in hint and "--urdf ROBOT.urdf --tip LINK" in hint
    assert all(n in hint for n in named & {"scale", "affine", "smooth_field"})
    tested = diagnose(m, robot="ur5", tool_mm=TOOL_MM, seed=0)
    assert "kinematic" in {e.name for e in tested.effects}
    assert not [x for x in tested.limits if "no arm model was tested" in x]


def test_a_scale_beyond_an_instruments_is_called_implausible_and_a_small_one_is_not():
    m = joint_measurements(1, n_fid=20, n_chk=10)

    def scale(ppm: float) -> dict:
        return {"scale": Effect("scale", {"ppm": ppm}, 1e-9, "")}

    big = arm_untested_hint(m, False, scale(-724.0))
    assert big is not None and "-724 ppm is more than a laser tracker" in big
    small = arm_untested_hint(m, False, scale(4.0))
    assert small is not None and "ppm is more than" not in small
    assert arm_untested_hint(m, True, scale(-724.0)) is None  # the arm was tested: nothing to hint
