"""The VEC study's cells (rrbc_core.studies.vec_study): its simulator writes the joint columns `rrbc calibrate`
reads, and a small grid runs end to end with the expected winner per scenario."""

from rrbc_core.io.joints import joint_angles
from rrbc_core.studies import vec_study


def test_a_small_grid_gives_vec_for_the_arm_and_rrbc_for_the_field():
    m = vec_study.joint_measurements(4, n_fid=12)
    assert joint_angles(m).shape == (len(m.ids), 6)
    rows = vec_study.run(
        scenarios={"kinematic": {"dh_size": 1.0}, "sensor field": {"dh_size": 0.0, "field_mm": 0.4}},
        fiducials=(20,),
        noises=(0.02,),
        seeds=(4,),
    )
    by = {r["scenario"]: r for r in rows}
    assert by["kinematic"]["best"] == "vec" and by["kinematic"]["kinematic_claimed"]
    assert by["sensor field"]["best"] == "rrbc" and not by["sensor field"]["kinematic_claimed"]
