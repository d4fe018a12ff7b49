"""Sources the app opens (scene TOML, measurement CSV, optional mesh) and the files it hands out.

Every failure is an `InputError` with the core's one-line message; nothing here computes RRBC numbers.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from rrbc_core.errors import InputError
from rrbc_core.io.measurements import MeasurementSet, parse_measurements, read_measurements
from rrbc_core.io.measurements_write import write_measurements
from rrbc_core.io.mesh_file import check_mesh_file
from rrbc_core.io.scene import default_scene_path
from rrbc_core.io.scene_toml import load_scene
from rrbc_core.session.explorer import ExplorerSession

if TYPE_CHECKING:
    import trimesh

SCENE_SUFFIXES = (".toml",)


@dataclass
class Loaded:
    """A freshly opened source: its session, the cell mesh (robot frame, mm; None if there is none) and a label."""

    session: ExplorerSession
    mesh: trimesh.Trimesh | None
    label: str


def _is_scene(name: str, text_start: str = "") -> bool:
    suffix = Path(name).suffix.lower()
    if suffix in SCENE_SUFFIXES:
        return True
    if suffix == ".csv":
        return False
    return text_start.lstrip().startswith("[")


MESH_SUFFIXES = (".glb", ".gltf", ".stl", ".obj", ".ply", ".off")
MAX_OFFERED = 500  # files listed from the offered folders, at most


@dataclass(frozen=True)
class Library:
    """The folders the app may open files from (issue 16): the bundled scenes/ and the folders named on the command
    line. The File tab lists their scene (.toml) and measurement (.csv) files, and mesh files in them and one
    level down; nothing else on the server can be opened from a page (there is no free-text path). `roots`:
    resolved directories."""

    roots: tuple[Path, ...]

    @classmethod
    def of(cls, folders=(), source=None) -> Library:
        """scenes/ (the default scene's folder), the given folders (InputError if one is not a directory) and the
        folder of a source file given on the command line."""
        roots = [Path(default_scene_path()).resolve().parent]
        for f in folders:
            p = Path(f)
            if not p.is_dir():
                raise InputError(f"--data {f}: not a directory")
            roots.append(p.resolve())
        if source is not None and not isinstance(source, ExplorerSession):
            roots.append(Path(os.fspath(source)).resolve().parent)
        return cls(tuple(dict.fromkeys(roots)))

    def _scan(self, suffixes, depth: int) -> list[tuple[str, Path]]:
        out: list[tuple[str, Path]] = []
        for root in self.roots:
            found = [root.glob("*")] + ([root.glob("*/*")] if depth > 1 else [])
            for it in found:
                for p in sorted(it):
                    if len(out) >= MAX_OFFERED:
                        return out
                    if p.suffix.lower() in suffixes and p.is_file() and not p.is_symlink():
                        rp = p.resolve()
                        if rp.is_relative_to(root):  # never a link out of the folder
                            out.append((f"{root.name}/{rp.relative_to(root).as_posix()}", rp))
        return out

    def sources(self) -> list[tuple[str, Path]]:
        """(label, path) of the scene and measurement files offered."""
        return self._scan(SCENE_SUFFIXES + (".csv",), 1)

    def meshes(self) -> list[tuple[str, Path]]:
        """(label, path) of the mesh files offered (the folders and one level down)."""
        return self._scan(MESH_SUFFIXES, 2)

    def pick(self, label: str, meshes: bool = False) -> Path:
        """The path behind a label the File tab offered; InputError for anything else."""
        for name, path in self.meshes() if meshes else self.sources():
            if name == label:
                return path
        raise InputError(f"{str(label)[:80]!r} is not one of the files offered (folders: scenes/ and --data)")


def load_mesh(path) -> trimesh.Trimesh:
    """A mesh file (any format trimesh reads) as one trimesh.Trimesh, robot frame, mm: read as a scene's mesh is
    (`io.scene._load_mesh_file`: rrbc's bounded-memory readers where they take the file)."""
    import trimesh

    from rrbc_core.io.scene import _load_mesh_file

    p = Path(path)
    check_mesh_file(p)  # missing, too large, or declaring too many triangles: refused before it is parsed
    try:
        mesh = _load_mesh_file(p)
    except Exception as exc:  # noqa: BLE001 - trimesh raises many types for unreadable files
        raise InputError(
            f"{path}: cannot load as a mesh: {exc.__class__.__name__}: {' '.join(str(exc).split())}"
        ) from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise InputError(f"{path}: the file holds no triangles")
    return mesh


def load_source(source=None, mesh=None) -> Loaded:
    """Open a scene (.toml; None = the bundled default scene) or a measurement file (.csv), with an optional
    mesh file for measurement files (a scene names its own mesh)."""
    if source is None:
        source = default_scene_path()
    path = os.fspath(source)
    head = ""
    if Path(path).suffix.lower() not in SCENE_SUFFIXES + (".csv",):
        try:
            with open(path, encoding="utf-8", errors="replace") as fh:
                head = fh.read(200)
        except OSError:
            head = ""
    if _is_scene(path, head):
        if mesh is not None:
            raise InputError(f"{path}: a scene names its own mesh (scene.mesh); --mesh is for measurement files")
        scene = load_scene(path)
        return _from_scene(scene, f"scene {scene.name} ({Path(path).name})")
    mset = read_measurements(path)
    return _from_measurements(mset, mesh, f"measurements {Path(path).name}")


def _from_scene(scene, label: str) -> Loaded:
    from rrbc_core.session.edits import mark_saved

    session = ExplorerSession.from_scene(scene)
    session.evaluate()
    mark_saved(session)  # as its file has it: nothing unsaved yet
    return Loaded(session, scene.load_mesh(), label)


def scene_loaded(scene, label: str) -> Loaded:
    """A scene already in memory (one the app changed: the Model tab's extended scene) as a source."""
    return _from_scene(scene, label)


def _from_measurements(mset: MeasurementSet, mesh, label: str, station: str | None = None) -> Loaded:
    mesh_obj = load_mesh(mesh) if mesh is not None else None
    session = ExplorerSession.from_measurements(mset, mesh_path=None if mesh is None else Path(mesh), station=station)
    session.evaluate()
    if session.stations:
        k = session.stations.index(session.station) + 1
        label += f", station {session.station!r} ({k} of {len(session.stations)})"
    return Loaded(session, mesh_obj, label)


def load_station(loaded: Loaded, station: str) -> Loaded:
    """Another station of the file `loaded` opened (its mesh kept); InputError for a name the file does not have."""
    session = loaded.session
    if not session.stations:
        raise InputError("these data have no stations (no group column)")
    base = loaded.label.split(", station ")[0]
    fresh = ExplorerSession.from_measurements(
        session.file_mset, mesh_path=session.mesh_path, settings=session.settings, station=station
    )
    fresh.evaluate()
    if session.arm_spec is not None:  # the robot of `rrbc view data.csv --urdf`, posed at this station's joints
        from rrbc_core.session.arm import attach_arm

        attach_arm(fresh, *session.arm_spec)
    k = fresh.stations.index(fresh.station) + 1
    return Loaded(fresh, loaded.mesh, f"{base}, station {fresh.station!r} ({k} of {len(fresh.stations)})")


def safe_file_name(name: str, suffix: str | None = None, fallback: str = "cell") -> str:
    """A file name for an upload kept on the server, whatever a tab declared (a path, "..", a NUL byte, thousands
    of characters): the user's base name (letters, digits, '-', '_', '.'; at most 80), else `fallback`, with
    `suffix` (lower case; None: the name's own, letters and digits only, at most 10)."""
    import re

    base = Path(str(name).replace("\\", "/"))
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", base.stem).strip("._")[:80] or fallback
    if suffix is None:
        suffix = re.sub(r"[^a-z0-9]+", "", base.suffix.lower())[:10]
        suffix = "." + suffix if suffix else ""
    return stem + suffix


def load_upload(name: str, content: bytes) -> Loaded:
    """Open an uploaded file: a measurement CSV is parsed as it is; a scene TOML is read from a temporary
    directory, so a mesh it names by a relative path will not be found (open such scenes by path)."""
    base = Path(name or "upload").name or "upload"
    try:
        text = content.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(
            f"{base}: not UTF-8 text (byte {exc.start}); upload a measurement CSV or a scene TOML"
        ) from None
    if _is_scene(base, text[:200]):
        with tempfile.TemporaryDirectory(prefix="rrbc-upload-") as tmp:
            path = Path(tmp) / (base if base.lower().endswith(".toml") else base + ".toml")
            path.write_text(text, encoding="utf-8")
            try:
                return _from_scene(load_scene(path), f"uploaded scene {base}")
            except InputError as exc:  # the message names the user's file, never the server's folders
                raise InputError(str(exc).replace(str(path), path.name).replace(tmp + os.sep, "")) from None
    return _from_measurements(parse_measurements(text, base), None, f"measurements {base} (uploaded)")


def measurements_csv(mset: MeasurementSet, comments=()) -> str:
    """A MeasurementSet as measurement-file text: written with the core's writer to a temporary file and read
    back, so the download is byte-for-byte what `write_measurements` produces."""
    with tempfile.TemporaryDirectory(prefix="rrbc-export-") as tmp:
        path = Path(tmp) / "export.csv"
        write_measurements(path, mset, comments=comments)
        return path.read_text(encoding="utf-8")


def slug(name: str) -> str:
    """A file-name stem from a session's name (letters, digits, _ . - kept; "rrbc" if nothing is left)."""
    import re

    return re.sub(r"[^A-Za-z0-9_.-]+", "-", str(name)).strip("-.") or "rrbc"
