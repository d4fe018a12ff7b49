"""Text mesh files (Wavefront OBJ, OFF) read in bounded memory (issue 42: trimesh's text parsers held 6x an OBJ's
size and 15x an OFF's at their peak while reading it).

Both readers give the file's own vertices (V, 3) float64 and triangles (F, 3) int64 (zero-based), with no vertex
merged or dropped, as trimesh's readers do with ``process=False``; a polygon becomes a fan of triangles from its first
corner. Numbers are parsed by numpy's C parser a block of lines at a time (`BLOCK_BYTES`), so the memory beyond the
mesh's own arrays is one block's text and its numbers. A file these readers do not take (an OFF with comments or
colours, an OBJ face with a relative, negative index, any number that does not parse) gives None: trimesh then reads
it as before. Robot frame, mm (as the file says).
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np

#: the text read and parsed at a time by `read_obj`
BLOCK_BYTES = 1 << 20

_SLASHES = re.compile(rb"/\S*")  # a face corner's texture and normal indices: "7/3/2" -> "7"


def _numbers(text: bytes, dtype=float) -> np.ndarray | None:
    """The whitespace-separated numbers of `text` (numpy's C parser), or None when any token is not one."""
    if not text.strip():
        return np.zeros(0, dtype)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy warns (and stops) at the first token it cannot read
        try:
            return np.fromstring(text, dtype=dtype, sep=" ")
        except (ValueError, DeprecationWarning):
            return None


def _fans(counts: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """Triangles (T, 3) of polygons with `counts` (P,) corners each, listed one after another in `corners`: a fan
    from each polygon's first corner."""
    if np.all(counts == 3):
        return corners.reshape(-1, 3)
    if np.any(counts < 3):
        raise ValueError("a face with fewer than three corners")
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    fans = counts - 2
    first = np.repeat(start, fans)
    k = np.arange(int(fans.sum())) - np.repeat(np.cumsum(fans) - fans, fans)  # 0, 1, .. within each polygon
    return np.column_stack([corners[first], corners[first + k + 1], corners[first + k + 2]])


def read_off(path) -> tuple[np.ndarray, np.ndarray] | None:
    """An OFF file's vertices and triangles (module docstring), or None where trimesh is left to read it (a header
    other than ``OFF``, comments, colours or other values after a face's corners)."""
    data = Path(path).read_bytes()
    if not data.startswith(b"OFF") or data[3:4] not in (b"\n", b"\r", b" ", b"\t") or b"#" in data:
        return None
    nums = _numbers(data[3:])
    del data
    if nums is None or len(nums) < 3:
        return None
    nv, nf = int(nums[0]), int(nums[1])
    body = nums[3:]
    if nv < 0 or nf < 0 or len(body) < 3 * nv:
        return None
    vertices = body[: 3 * nv].reshape(nv, 3).copy()
    rest = body[3 * nv :]
    del nums, body
    counts, corners, at = [], [], 0
    if nf and len(rest) == 4 * nf and np.all(rest[0::4] == 3):  # all triangles: one reshape
        faces = rest.reshape(nf, 4)[:, 1:]
    else:
        for _ in range(nf):  # polygons: each face's count, then its corners
            if at >= len(rest):
                return None
            c = int(rest[at])
            counts.append(c)
            corners.append(rest[at + 1 : at + 1 + c])
            at += 1 + c
        if at != len(rest):
            return None  # colours or other values after the corners
        faces = _fans(np.asarray(counts), np.concatenate(corners)) if nf else np.zeros((0, 3))
    return vertices, _indices(faces, nv, 0)


def _indices(faces: np.ndarray, nv: int, base: int) -> np.ndarray:
    """Triangles as int64 zero-based indices, checked: whole numbers that name a vertex."""
    if faces.dtype.kind == "f":
        if faces.size and np.any(faces != np.round(faces)):
            raise ValueError("a face names a vertex by a number that is not whole")
        faces = faces.astype(np.int64)
    out = faces - base if base else faces
    if out.size and (out.min() < 0 or out.max() >= nv):
        raise ValueError("a face names a vertex the file does not have")
    return out.reshape(-1, 3)


def read_obj(path) -> tuple[np.ndarray, np.ndarray, list[tuple[str, int, int]]] | None:
    """A Wavefront OBJ's vertices, triangles and parts ((name, first face, end face): its ``o`` objects, else its
    ``g`` groups, else the whole file under its name), or None where trimesh is left to read it (a relative,
    negative index, or a number that does not parse). Texture coordinates, normals, materials, lines and points are
    not read."""
    p = Path(path)
    vertices: list[np.ndarray] = []
    faces: list[np.ndarray] = []
    marks: dict[bytes, list[tuple[str, int]]] = {b"o": [], b"g": []}
    nv = nf = 0
    with open(p, "rb") as f:
        tail = b""
        while True:
            block = f.read(BLOCK_BYTES)
            text = tail + block
            if block:
                cut = text.rfind(b"\n") + 1
                text, tail = text[:cut], text[cut:]
            else:
                tail = b""
            vs, fs, starts = _block_lines(text)
            if vs:
                v = _numbers(b"\n".join(vs))
                if v is None or len(v) != 3 * len(vs):  # a w or colour after x y z: the first three of each
                    rows = [line.split()[:3] for line in vs]
                    if any(len(r) != 3 for r in rows):
                        return None
                    v = _numbers(b" ".join(b" ".join(r) for r in rows))
                    if v is None:
                        return None
                vertices.append(v.reshape(-1, 3))
                nv += len(vs)
            counts = np.fromiter((len(line.split()) for line in fs), dtype=np.int64, count=len(fs))
            # triangles before each face line of the block (a polygon of k corners makes k - 2)
            before = np.concatenate([[0], np.cumsum(np.maximum(counts - 2, 0))])
            for kind, name, lines_before in starts:  # where an object or group starts
                marks[kind].append((name, nf + int(before[lines_before])))
            if fs:
                idx = _numbers(_SLASHES.sub(b"", b"\n".join(fs)), np.int64)
                if idx is None or len(idx) != int(counts.sum()) or (len(idx) and idx.min() < 1):
                    return None  # unreadable, or a relative (negative) index
                tri = _fans(counts, idx)
                faces.append(tri)
                nf += len(tri)
            if not block:
                break
    v_all = np.concatenate(vertices) if vertices else np.zeros((0, 3))
    f_all = np.concatenate(faces) if faces else np.zeros((0, 3), np.int64)
    del vertices, faces
    tri = _indices(f_all, len(v_all), 1)
    return v_all, tri, _parts(marks[b"o"] or marks[b"g"], len(tri), p.name)


def _block_lines(text: bytes) -> tuple[list[bytes], list[bytes], list[tuple[bytes, str, int]]]:
    """A block's vertex lines' and face lines' values (after ``v``/``f``), and its object and group lines: (kind
    b"o" or b"g", name, face lines before it in the block)."""
    vs: list[bytes] = []
    fs: list[bytes] = []
    starts: list[tuple[bytes, str, int]] = []
    for line in text.split(b"\n"):
        head = line[:2]
        if head in (b"v ", b"v\t"):
            vs.append(line[2:])
        elif head in (b"f ", b"f\t"):
            fs.append(line[2:])
        elif head in (b"o ", b"g "):
            starts.append((head[:1], line[2:].strip().decode("utf-8", "replace") or "part", len(fs)))
    return vs, fs, starts


def _parts(marks: list[tuple[str, int]], n_faces: int, fallback: str) -> list[tuple[str, int, int]]:
    """(name, first, end) of each non-empty run of faces between the marks (faces before the first mark: the file's
    name)."""
    starts = [(fallback, 0)] + [(name, at) for name, at in marks]
    out = []
    for k, (name, at) in enumerate(starts):
        end = starts[k + 1][1] if k + 1 < len(starts) else n_faces
        if end > at:
            out.append((name, at, end))
    return out or [(fallback, 0, n_faces)]
