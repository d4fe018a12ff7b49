"""The cell's mesh in the 3-D scene: one solid and one see-through node, one of them shown.

The mesh is sent twice (the solid with trimesh's own material, the see-through one as float32 vertices and uint32
triangles), so an accepted upload costs its reading plus these two messages: tests/io/test_mesh_file.py holds the
whole under 3x the file's size (issue 42). Robot frame, mm.
"""

from __future__ import annotations

import numpy as np
import viser

#: the see-through cell's colour and opacity: it shows what lies under surfaces
GHOST_COLOR = (170, 170, 175)
GHOST_OPACITY = 0.18


def add_cell_mesh(scene: viser.SceneApi, mesh, see_through: bool) -> dict[str, object]:
    """Add the cell's `mesh` (a trimesh.Trimesh) as /mesh/cell (solid) and /mesh/ghost (see-through), the one
    `see_through` asks for visible. Returns the two handles by node name."""
    return {
        "/mesh/cell": scene.add_mesh_trimesh(
            "/mesh/cell", mesh, cast_shadow=False, receive_shadow=False, visible=not see_through
        ),
        "/mesh/ghost": scene.add_mesh_simple(
            "/mesh/ghost",
            np.asarray(mesh.vertices, np.float32),
            np.asarray(mesh.faces, np.uint32),
            color=GHOST_COLOR,
            opacity=GHOST_OPACITY,
            side="double",
            cast_shadow=False,
            receive_shadow=False,
            visible=see_through,
        ),
    }
