"""The real robot in the page (issue 30): the default scene's UR5 drawn from the URDF and meshes example-robot-data
ships, its meshes mounted in the browser's scene and posed so that the flange carries the tool point to the
selected target (within 1 mm), read from the page's own three.js scene."""

from __future__ import annotations

import numpy as np
import pytest

from rrbc_viz.serve import serve

from .helpers import lighting, wait_for

pytestmark = pytest.mark.browser

# A node's origin and its z axis's tip (1 unit out) in the robot frame (the frame of the cell's mesh node '/mesh').
_JS_FRAME = """(name) => { const m = window.__viserMutable; const o = m.nodeRefFromName[name];
  const base = m.nodeRefFromName['/mesh']; if (!o || !base) return null;
  o.updateWorldMatrix(true, false); base.updateWorldMatrix(true, false); const V = o.position.constructor;
  const p = base.worldToLocal(o.localToWorld(new V(0, 0, 0)));
  const z = base.worldToLocal(o.localToWorld(new V(0, 0, 1)));
  return [[p.x, p.y, p.z], [z.x - p.x, z.y - p.y, z.z - p.z]]; }"""
_JS_URDF_MESHES = """() => Object.keys(window.__viserMutable.nodeRefFromName).filter(
  (n) => n.startsWith('/arm/urdf/visual/') && window.__viserMutable.nodeRefFromName[n].isObject3D)"""


def test_the_ur5_is_drawn_from_its_urdf_meshes_and_posed_on_the_target(viser_app, page_for):
    app = viser_app(lambda: serve())
    page, _ = page_for(app.url)
    arm = app.nodes.arm_nodes()
    assert arm is not None and arm.urdf is not None
    mesh_names = {h.name for h in arm.urdf._meshes}
    wait_for(lambda: mesh_names <= set(page.evaluate(_JS_URDF_MESHES)), 60, message="the arm's meshes", page=page)
    # `rrbc view` without --plain-light lights the meshes with the environment map and adds no hemisphere light
    wait_for(lambda: lighting(page) == (True, 0), 30, message="the environment map", page=page)
    flange = next(f.name for f in arm.urdf._joint_frames if f.name.endswith("/tool0"))
    tool_mm = app.session.scene.tool_mm
    t = app.session.last.targets
    for target in ("H1", "H6"):
        app.views.select("targets", target)
        goal = t.positions[list(t.ids).index(target)]

        def tool_at_goal(goal=goal):
            got = page.evaluate(_JS_FRAME, flange)
            if got is None:
                return False
            origin, z = np.array(got[0]), np.array(got[1])
            tool = origin + tool_mm * z / np.linalg.norm(z)
            return np.linalg.norm(tool - goal) < 1.0

        wait_for(tool_at_goal, 30, message=f"the flange's tool point on {target} in the page", page=page)
