"""A 3MF mesh (a zip archive holding the model as XML) read while it is unpacked (issue 42: trimesh's reader held the
whole XML tree, 18x the archive's size at its peak).

The model's XML is parsed as a stream (the standard library's expat parser, whose entity expansion is bounded); each
vertex and triangle is kept only as its numbers (8 bytes each) and its element dropped at once. Objects placed by the
model's build items (with their transforms) make the mesh, one part per item. A model this reader does not take
(components, objects from other model files, no build item, a value that does not parse) gives None: trimesh then
reads it as before. The archive's sizes were checked before (`io.mesh_file.check_mesh_file`). Units as the file says
(like trimesh's reader, no scaling).
"""

from __future__ import annotations

import zipfile
from array import array
from pathlib import Path
from xml.etree.ElementTree import ParseError, iterparse

import numpy as np


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _transform(text: str | None) -> np.ndarray:
    """A build item's transform (4, 4) from its 12 numbers (3MF: column by column of a 4 x 3 matrix)."""
    m = np.eye(4)
    if text:
        values = np.array(text.split(), float)
        if values.shape != (12,):
            raise ValueError("a transform of other than 12 numbers")
        m[:3, :4] = values.reshape(4, 3).T
    return m


def read_3mf(path) -> tuple[np.ndarray, np.ndarray, list[tuple[str, int, int]]] | None:
    """The model's vertices (V, 3) float64, triangles (F, 3) int64 and parts ((name, first face, end face) per build
    item), or None where trimesh is left to read it (module docstring)."""
    with zipfile.ZipFile(Path(path)) as z:
        names = [n for n in z.namelist() if n.lower().endswith("3dmodel.model")]
        if len(names) != 1:
            return None
        with z.open(names[0]) as f:
            parsed = _parse(f)
    if parsed is None:
        return None
    v, t, objects, items = parsed
    vertices, faces, parts, nv, nf = [], [], [], 0, 0
    for object_id, matrix in items:
        if object_id not in objects:
            return None
        name, (v0, v1), (t0, t1) = objects[object_id]
        pts = v[v0:v1]
        pts = pts @ matrix[:3, :3].T + matrix[:3, 3]
        tri = t[t0:t1]
        if tri.size and (tri.min() < 0 or tri.max() >= v1 - v0):
            raise ValueError("a triangle names a vertex its object does not have")
        vertices.append(pts)
        faces.append(tri + nv)
        parts.append((name, nf, nf + len(tri)))
        nv, nf = nv + len(pts), nf + len(tri)
    if not items:
        return None
    return np.concatenate(vertices), np.concatenate(faces), [p for p in parts if p[2] > p[1]]


def _parse(stream):
    """(vertices (V, 3), triangles (T, 3) indices within their object, {object id: (name, vertex range, triangle
    range)}, [(object id, transform)]) of a model's XML, or None (components, or a value that does not parse)."""
    coords, corners = array("d"), array("q")
    objects: dict[str, tuple[str, tuple[int, int], tuple[int, int]]] = {}
    items: list[tuple[str, np.ndarray]] = []
    current: tuple[str, str, int, int] | None = None
    holder = None  # the <vertices> or <triangles> element whose children are dropped as they are read
    try:
        for event, elem in iterparse(stream, events=("start", "end")):
            tag = _local(elem.tag)
            if event == "start":
                if tag in ("vertices", "triangles"):
                    holder = elem
                elif tag == "object":
                    oid = elem.get("id", "")
                    current = (oid, elem.get("name") or f"object {oid}", len(coords) // 3, len(corners) // 3)
                elif tag in ("component", "components"):
                    return None
                continue
            if tag == "vertex":
                a = elem.attrib
                coords.extend((float(a["x"]), float(a["y"]), float(a["z"])))
            elif tag == "triangle":
                a = elem.attrib
                corners.extend((int(a["v1"]), int(a["v2"]), int(a["v3"])))
            elif tag == "object" and current is not None:
                oid, name, v0, t0 = current
                objects[oid] = (name, (v0, len(coords) // 3), (t0, len(corners) // 3))
                current = None
                elem.clear()
            elif tag == "item":
                items.append((elem.get("objectid", ""), _transform(elem.get("transform"))))
            if holder is not None and tag in ("vertex", "triangle"):
                holder.clear()  # the element read is dropped: memory stays its numbers
    except (ParseError, KeyError, ValueError):
        return None
    v = np.frombuffer(coords, dtype=np.float64).reshape(-1, 3)
    t = np.frombuffer(corners, dtype=np.int64).reshape(-1, 3)
    if not np.all(np.isfinite(v)):
        raise ValueError("the file holds coordinates that are not finite numbers")
    return v, t, objects, items
