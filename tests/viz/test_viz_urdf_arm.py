"""A measured file's robot given by a URDF with no geometry of its own (issue 39: `rrbc view data.csv --urdf
robot.urdf` drew nothing and said nothing): the arm is drawn as links between its joints, posed at the selected
point's joint values, and the terminal says why."""

import numpy as np

from rrbc_core.io.measurements_write import write_measurements
from rrbc_core.models.urdf import load_urdf
from rrbc_core.simulation.arm_data import chain_measurements
from rrbc_viz.serve import serve


def test_a_urdf_without_geometry_is_drawn_as_links_between_its_joints(tmp_path, capsys):
    chain = load_urdf("lift_arm")  # written without visual or collision elements
    data = tmp_path / "lift.csv"
    write_measurements(data, chain_measurements(chain, 2, n_fid=12, n_chk=6, n_tgt=2, noise_mm=0.05))
    app = serve(data, port=0, urdf="lift_arm")
    try:
        assert "has neither visual nor collision geometry" in capsys.readouterr().err
        arm = app.nodes.arm_nodes()
        assert arm is not None and arm.urdf is None and arm.chain_links
        pid = app.session.layout["targets"].ids[0]
        app.views.select("targets", pid)
        desc = app.session.arm
        pose_q = app.session.arm_joints[("targets", pid)]
        pts = desc.joint_points(pose_q)
        shown = [link for link in arm.links if link.visible]
        assert len(shown) >= len(chain.joints) // 2
        for i, link in enumerate(arm.links):
            if link.visible:  # each drawn link spans two successive joint origins
                np.testing.assert_allclose(link.position, 0.5 * (pts[i] + pts[i + 1]), atol=1e-6)
                assert abs(link.height - np.linalg.norm(pts[i + 1] - pts[i])) < 1e-6
        np.testing.assert_allclose(arm.pose.commanded, desc.tool_point(pose_q), atol=1e-9)
    finally:
        app.stop()
