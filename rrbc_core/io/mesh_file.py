"""How large a mesh file is, read before it is parsed: its size, and the triangles its header (or a streamed count)
declares, so that a mesh too large for the app (`MESH_MAX_BYTES`, `MESH_MAX_FACES`) is refused in bounded memory
and time, before a mesh reader unpacks or parses it (issue 42: a 0.3 MB 3MF holding 3 M triangles peaked at 3 GB).
Every mesh the library or the app loads goes through `check_mesh_file` (or, for an upload in progress,
`refuse_from_header` on its first bytes). A binary STL is read here too (`read_binary_stl`), in a few times its size.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rrbc_core.errors import InputError

MESH_MAX_BYTES = 200 << 20
MESH_MAX_FACES = 2_000_000


def check_mesh_file(path) -> None:
    """InputError when the mesh file is missing, larger than `MESH_MAX_BYTES`, would unpack to more (a 3MF), or
    declares more than `MESH_MAX_FACES` triangles (`declared_triangles`)."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: mesh file not found")
    size = p.stat().st_size
    why = _too_large(str(p), size, declared_triangles(p) if size <= MESH_MAX_BYTES else None)
    if why is not None:
        raise InputError(why)


def declared_triangles(path) -> int | None:
    """The number of triangles a mesh file says it holds, read without parsing the mesh (bounded memory): a binary
    STL's count field, an ASCII STL's facets, a PLY header's face element, an OBJ's face lines (at least one
    triangle each), a 3MF's triangle elements (`_zip_triangles`: refused first when its archive would unpack to more
    than `MESH_MAX_BYTES`), a GLB's triangle primitives (`_glb_triangles`); None for other formats or a file that
    says nothing readable."""
    p = Path(path)
    suffix = p.suffix.lower()
    size = p.stat().st_size
    if suffix == ".3mf":
        return _zip_triangles(p)
    if suffix == ".glb":
        return _glb_triangles(p)
    with open(p, "rb") as f:
        head = f.read(512)
        n = header_triangles(suffix, head, size)
        if n is not None:
            return n
        if suffix == ".stl" and head.lstrip()[:5].lower() == b"solid":
            return _count(f, b"facet normal")
        if suffix == ".obj":
            return _count(f, b"\nf ")
    return None


def _zip_triangles(p: Path) -> int | None:
    """A 3MF (a zip archive): InputError when its members would unpack to more than `MESH_MAX_BYTES` (what the
    archive declares; the reader never unpacks more than a member declares), else the `<triangle>` elements of its
    models, counted while streaming them (memory: one chunk; the count stops past `MESH_MAX_FACES`). None when it is
    not a readable archive (the mesh reader then says what is wrong)."""
    import zipfile

    try:
        with zipfile.ZipFile(p) as z:
            infos = z.infolist()
            total = sum(i.file_size for i in infos)
            if total > MESH_MAX_BYTES:
                raise InputError(
                    f"{p}: the 3MF archive unpacks to {total >> 20} MiB; at most {MESH_MAX_BYTES >> 20} MiB unpacked "
                    "(export a decimated mesh; a small file that unpacks this far is not a mesh)"
                )
            n = 0
            for info in infos:
                if info.filename.lower().endswith(".model"):
                    with z.open(info) as f:
                        n += _count(f, b"v1=", limit=MESH_MAX_FACES - n)
                if n > MESH_MAX_FACES:
                    break
            return n
    except InputError:
        raise
    except (zipfile.BadZipFile, OSError, EOFError, ValueError, NotImplementedError):
        return None


def _glb_triangles(p: Path) -> int | None:
    """A binary glTF's triangles from its JSON chunk alone (accessor counts of its triangle primitives, a mesh
    counted once per node that places it), before any buffer is read; None when the header says nothing
    readable."""
    import json

    try:
        with open(p, "rb") as f:
            head = f.read(20)
            if len(head) < 20 or head[:4] != b"glTF" or head[16:20] != b"JSON":
                return None
            length = int.from_bytes(head[12:16], "little")
            if length > 64 << 20:  # a JSON chunk of this size is not a mesh's description
                return None
            doc = json.loads(f.read(length))
        accessors = doc.get("accessors", [])
        uses = [0] * len(doc.get("meshes", []))
        for node in doc.get("nodes", []):
            if isinstance(node.get("mesh"), int) and 0 <= node["mesh"] < len(uses):
                uses[node["mesh"]] += 1
        n = 0
        for k, mesh in enumerate(doc.get("meshes", [])):
            for prim in mesh.get("primitives", []):
                mode = prim.get("mode", 4)
                idx = prim.get("indices", prim.get("attributes", {}).get("POSITION"))
                count = int(accessors[idx]["count"])
                n += max(uses[k], 1) * (count // 3 if mode == 4 else max(count - 2, 0) if mode in (5, 6) else 0)
        return n
    except (OSError, ValueError, KeyError, IndexError, TypeError, AttributeError):
        return None


def header_triangles(suffix: str, head: bytes, size: int) -> int | None:
    """The triangle count a mesh file's first bytes `head` declare (a file of `size` bytes, name ending in
    `suffix`): a binary STL's count field (when it agrees with the size), a PLY header's face element; None when
    the head alone does not say (other formats, ASCII STL, OBJ)."""
    suffix = suffix.lower()
    if suffix == ".stl" and len(head) >= 84:
        n = int.from_bytes(head[80:84], "little")
        if 84 + 50 * n == size:  # binary: the count field agrees with the file's length
            return n
    if suffix == ".ply" and head.startswith(b"ply"):
        for line in head[:4096].split(b"\n"):
            parts = line.split()
            if len(parts) == 3 and parts[0] == b"element" and parts[1] == b"face" and parts[2].isdigit():
                return int(parts[2])
            if line.strip() == b"end_header":
                break
    return None


def refuse_from_header(name: str, head: bytes, size: int) -> str | None:
    """Why an upload of a mesh file must be refused from its size and first bytes alone (too large, or declaring
    more than `MESH_MAX_FACES` triangles), or None."""
    return _too_large(name, size, header_triangles(Path(name).suffix, head, size) if size <= MESH_MAX_BYTES else None)


def _too_large(name: str, size: int, declared: int | None) -> str | None:
    """The one refusal of a mesh file over `MESH_MAX_BYTES` or declaring over `MESH_MAX_FACES` triangles."""
    if size > MESH_MAX_BYTES:
        return f"{name}: mesh file larger than {MESH_MAX_BYTES >> 20} MiB; decimate it first"
    if declared is not None and declared > MESH_MAX_FACES:
        return f"{name}: {declared} triangles; at most {MESH_MAX_FACES} (decimate it first)"
    return None


def _count(f, token: bytes, chunk: int = 1 << 22, limit: int | None = None) -> int:
    """Occurrences of `token` in an open binary file or stream, read from its start in chunks (memory: one chunk);
    with `limit`, it stops once the count passes it."""
    if f.seekable():
        f.seek(0)
    n, tail = 0, b""
    while True:
        block = f.read(chunk)
        if not block or (limit is not None and n > limit):
            return n
        data = tail + block  # a token across the boundary starts in the tail, shorter than the token
        n += data.count(token)
        tail = data[-(len(token) - 1) :] if len(token) > 1 else b""


#: triangles read (and corners compared) at a time by `read_binary_stl`
STL_CHUNK = 1 << 18


def read_binary_stl(path) -> tuple[np.ndarray, np.ndarray] | None:
    """A binary STL's vertices (V, 3) float64 and triangles (F, 3) int64, corners with identical coordinates merged
    into one vertex (the vertices in the order of their bytes, as `np.unique` of the corners' bytes gives them);
    None when the file is not a binary STL (its count field disagrees with its length).

    Memory: the records are read `STL_CHUNK` at a time into one float32 array of corners (0.72x the file); the
    corners are merged through one stable sort of their bytes, whose order (8 bytes a corner) and the int32 vertex
    index are the only other arrays as large; so the peak is about 2x the file's size
    (tests/io/test_mesh_file.py holds the traced peak).

    Raises
    ------
    ValueError
        A coordinate that is not finite.
    """
    p = Path(path)
    size = p.stat().st_size
    with open(p, "rb") as f:
        head = f.read(84)
        n = header_triangles(".stl", head, size)
        if n is None:
            return None
        record = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])
        corners = np.empty((3 * n, 3), np.float32)
        for start in range(0, n, STL_CHUNK):
            k = min(STL_CHUNK, n - start)
            block = np.fromfile(f, dtype=record, count=k)["corners"].reshape(-1, 3)
            if len(block) != 3 * k:
                raise ValueError("the file ends before its last triangle")
            if not np.all(np.isfinite(block)):
                raise ValueError("the file holds coordinates that are not finite numbers")
            corners[3 * start : 3 * (start + k)] = block
    keys = corners.view(np.dtype((np.void, 12))).ravel()
    order = np.argsort(keys, kind="stable")  # the order np.unique sorts in
    new = np.empty(len(keys), bool)  # the first corner of each run of equal bytes in that order
    new[:1] = True
    for lo in range(1, len(keys), STL_CHUNK):
        hi = min(lo + STL_CHUNK, len(keys))
        new[lo:hi] = keys[order[lo:hi]] != keys[order[lo - 1 : hi - 1]]
    index = np.empty(len(keys), np.int32)
    index[order] = np.cumsum(new, dtype=np.int32) - 1
    first = order[new]
    del order, new
    vertices = corners[first].astype(np.float64)
    del corners, keys
    return vertices, index.reshape(-1, 3).astype(np.int64)
