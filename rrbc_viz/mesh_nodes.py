"""The cell's mesh in the 3-D scene: a solid node or a see-through one, only the one shown.

The solid node carries trimesh's own material (sent as a binary glTF), the see-through one float32 vertices and
uint32 triangles with one colour. Only the node shown exists: switching sends the mesh again as the other (issue 42:
the server kept both messages, each about the mesh's size, for every cell it showed). An accepted upload costs its
reading plus one message: tests/io/test_mesh_file.py holds the whole. Robot frame, mm.
"""

from __future__ import annotations

import numpy as np
import viser

#: the see-through cell's colour and opacity: it shows what lies under surfaces
GHOST_COLOR = (170, 170, 175)
GHOST_OPACITY = 0.18

#: the scene node of each look
SOLID_NODE, GHOST_NODE = "/mesh/cell", "/mesh/ghost"


def add_cell_mesh(scene: viser.SceneApi, mesh, see_through: bool) -> dict[str, object]:
    """Add the cell's `mesh` (a trimesh.Trimesh) as the solid node (`SOLID_NODE`) or the see-through one
    (`GHOST_NODE`), as `see_through` asks. Returns {node name: handle}."""
    if not see_through:
        from trimesh.exchange.gltf import export_glb

        # (trimesh's glTF bytes, without viser's copy of them through a BytesIO: `add_mesh_trimesh` less a copy)
        glb = export_glb(mesh)
        return {SOLID_NODE: scene.add_glb(SOLID_NODE, glb_data=glb, cast_shadow=False, receive_shadow=False)}
    return {
        GHOST_NODE: scene.add_mesh_simple(
            GHOST_NODE,
            np.asarray(mesh.vertices, np.float32),
            np.asarray(mesh.faces, np.uint32),
            color=GHOST_COLOR,
            opacity=GHOST_OPACITY,
            side="double",
            cast_shadow=False,
            receive_shadow=False,
        )
    }
