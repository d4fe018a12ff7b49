"""Bringing a user's own cell in: `rrbc scene new` (a complete scene from a mesh and a target list), the targets
file, where markers can go on the mesh (`cell_geometry`)."""
