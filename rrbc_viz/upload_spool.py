"""Uploads written to disk part by part, measured before they are parsed (issue 31, item 2).

viser 1.1.1 keeps every part of an upload in memory and joins them (twice the file's size) before the button's
callback sees the bytes; a 200 MB mesh that was then refused peaked at 3.1 GB. For the upload buttons given to
`spool` the transfer is taken over instead: the browser's first message declares the file's name and size, and a
file larger than the button's limit is refused there - its parts are dropped as they arrive, never kept. An
accepted file is written to a temporary folder as its parts arrive (memory: one part, 512 KiB from viser's
client), the first part is shown to the button's `check` (a mesh's header: its triangle count) so a file the app
would refuse is refused before the rest is stored, and the whole file is handed to `on_file(client, name, path)`
on viser's thread pool. The folder is the callback's to keep or remove; a refused, broken or abandoned transfer
(the tab closed: `drop_client`) leaves nothing behind, nor does the app's `close`. At most
`MAX_ACTIVE_PER_CLIENT` transfers of a tab and `MAX_ACTIVE` in all are stored at once.

Hooks: viser's `GuiApi` handles `FileTransferStartUpload` and `FileTransferPart` in two methods registered with its
websocket interface; `spool` puts a wrapper in their place that takes the spooled buttons' transfers and hands every
other one to viser's own handler (viser pinned; tests/viz/test_upload_spool.py drives real websocket uploads).
"""

from __future__ import annotations

import os
import shutil
import tempfile
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from viser import _messages

from .sources import safe_file_name

#: Transfers stored at once, per tab and in all.
MAX_ACTIVE_PER_CLIENT = 2
MAX_ACTIVE = 8


@dataclass
class _Button:
    max_bytes: int
    on_file: Callable[[Any, str, Path], object]
    on_refused: Callable[[Any, str], object]
    check: Callable[[str, bytes, int], str | None] | None = None


@dataclass
class _Transfer:
    client_id: int
    button: str
    name: str
    size: int
    part_count: int
    folder: Path
    path: Path
    fd: int
    got: set = field(default_factory=set)
    stored: int = 0
    chunk: int | None = None  # the length of every part but the last (viser's client sends equal parts)
    last_len: int | None = None


class _Spool:
    """The spooled buttons of one viser GuiApi and their transfers in flight."""

    def __init__(self, gui):
        self.gui = gui
        self.lock = threading.Lock()
        self.buttons: dict[str, _Button] = {}
        self.active: dict[str, _Transfer] = {}
        self.refused: dict[str, int] = {}  # transfer uuid -> client id: its parts are dropped
        ws = gui._websock_interface
        self._viser_start = gui._handle_file_transfer_start
        self._viser_part = gui._handle_file_transfer_part
        ws.unregister_handler(_messages.FileTransferStartUpload, self._viser_start)
        ws.unregister_handler(_messages.FileTransferPart, self._viser_part)
        ws.register_handler(_messages.FileTransferStartUpload, self._start)
        ws.register_handler(_messages.FileTransferPart, self._part)

    # ------------------------------------------------------------------------------------------ messages
    def _start(self, client_id, message) -> None:
        button = self.buttons.get(message.source_component_uuid)
        if button is None:
            self._viser_start(client_id, message)
            return
        name = safe_file_name(str(message.filename), fallback="upload")  # a tab may declare any name
        size, parts = int(message.size_bytes), int(message.part_count)
        why = None
        if size > button.max_bytes:
            why = f"{name}: {size / 2**20:.0f} MiB; at most {button.max_bytes >> 20} MiB (decimate or split it first)"
        elif size <= 0 or parts <= 0:
            why = f"{name}: the file is empty"
        else:
            with self.lock:
                mine = sum(1 for t in self.active.values() if t.client_id == client_id)
                if mine >= MAX_ACTIVE_PER_CLIENT or len(self.active) >= MAX_ACTIVE:
                    why = f"{name}: other uploads are still arriving; wait for them, then upload again"
                else:
                    folder = Path(tempfile.mkdtemp(prefix="rrbc-upload-"))
                    path = folder / name
                    try:
                        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
                    except OSError as exc:  # a full disk, a name the file system refuses: said, nothing left
                        shutil.rmtree(folder, ignore_errors=True)
                        why = f"{name}: cannot be stored here ({exc.strerror or exc}); upload it again"
                    else:
                        self.active[message.transfer_uuid] = _Transfer(
                            client_id, message.source_component_uuid, name, size, parts, folder, path, fd
                        )
        if why is not None:
            self._refuse(client_id, message.transfer_uuid, message.source_component_uuid, size, why)

    def _part(self, client_id, message) -> None:
        uuid = message.transfer_uuid
        with self.lock:
            if uuid in self.refused:
                return
            t = self.active.get(uuid)
        if t is None:
            self._viser_part(client_id, message)
            return
        if t.client_id != client_id:
            return  # another tab's transfer: not this client's to add to
        data = bytes(message.content)
        i = int(message.part_index)
        last = i == t.part_count - 1
        why = None
        if not (0 <= i < t.part_count) or i in t.got:
            return  # out of range or repeated: ignored, as viser does
        if not last:
            if t.chunk is None:
                t.chunk = len(data)
            if len(data) != t.chunk or len(data) == 0:
                why = f"{t.name}: the upload arrived broken (parts of unequal size); upload it again"
        offset = t.size - len(data) if last else i * (t.chunk or 0)
        if why is None and (offset < 0 or offset + len(data) > t.size):
            why = f"{t.name}: the upload arrived longer than the browser declared; upload it again"
        if why is None:
            os.pwrite(t.fd, data, offset)
            t.got.add(i)
            t.stored += len(data)
            if last:
                t.last_len = len(data)
            if i == 0:
                check = self.buttons[t.button].check
                why = check(t.name, data, t.size) if check is not None else None
        if why is not None:
            self._refuse(client_id, uuid, t.button, t.size, why)
            return
        self._ack(message.source_component_uuid, uuid, t.stored, t.size)
        if len(t.got) < t.part_count:
            return
        with self.lock:
            self.active.pop(uuid, None)
        os.close(t.fd)
        if t.stored != t.size or (
            t.part_count > 1 and (t.part_count - 1) * (t.chunk or 0) + (t.last_len or 0) != t.size
        ):
            shutil.rmtree(t.folder, ignore_errors=True)
            self._tell(client_id, self.buttons[t.button].on_refused, f"{t.name}: the upload arrived broken; again")
            return
        button = self.buttons[t.button]
        client = self.gui._resolve_client(client_id)
        if client is None:
            shutil.rmtree(t.folder, ignore_errors=True)
            return

        def hand_over() -> None:
            try:
                button.on_file(client, t.name, t.path)
            finally:
                shutil.rmtree(t.folder, ignore_errors=True)  # the callback moved what it keeps

        self.gui._thread_executor.submit(hand_over)

    # ------------------------------------------------------------------------------------------ helpers
    def _ack(self, button_uuid, uuid, done: int, total: int) -> None:
        self.gui._websock_interface.queue_message(
            _messages.FileTransferPartAck(
                source_component_uuid=button_uuid, transfer_uuid=uuid, transferred_bytes=done, total_bytes=total
            )
        )

    def _refuse(self, client_id, uuid, button_uuid, size: int, why: str) -> None:
        with self.lock:
            t = self.active.pop(uuid, None)
            self.refused[uuid] = client_id
            _discard([t] if t is not None else [])
        self._ack(button_uuid, uuid, max(size, 0), max(size, 0))  # the browser's progress ends; the note says why
        self._tell(client_id, self.buttons[button_uuid].on_refused, why)

    def _tell(self, client_id, on_refused, why: str) -> None:
        client = self.gui._resolve_client(client_id)
        if client is not None:  # a tab that closed hears nothing
            self.gui._thread_executor.submit(on_refused, client, why)

    def drop_client(self, client_id) -> None:
        """A tab closed: its transfers in flight go, and what they stored."""
        with self.lock:  # removed under the lock: an app stopping meanwhile (`close`) returns after this is gone
            gone = [u for u, t in self.active.items() if t.client_id == client_id]
            _discard([self.active.pop(u) for u in gone])
            for u in [u for u, c in self.refused.items() if c == client_id]:
                self.refused.pop(u)

    def close(self) -> None:
        """The app stops: every transfer in flight goes."""
        with self.lock:
            _discard(list(self.active.values()))
            self.active.clear()
            self.refused.clear()


def _discard(transfers) -> None:
    """Close and remove the stored part of each transfer (small: a folder with one partial file)."""
    for t in transfers:
        os.close(t.fd)
        shutil.rmtree(t.folder, ignore_errors=True)


_spools: dict[int, _Spool] = {}
_spools_lock = threading.Lock()


def spool(
    gui,
    button,
    max_bytes: int,
    on_file: Callable[[Any, str, Path], object],
    on_refused: Callable[[Any, str], object],
    check: Callable[[str, bytes, int], str | None] | None = None,
) -> None:
    """Take over the uploads of `button` (a viser upload button of `gui`): refused above `max_bytes` (or when
    `check(name, first_part, size)` returns a reason) with `on_refused(client, why)`, else written to disk and
    handed to `on_file(client, name, path)` (module docstring)."""
    with _spools_lock:
        s = _spools.get(id(gui))
        if s is None or s.gui is not gui:
            s = _spools[id(gui)] = _Spool(gui)
    s.buttons[button._impl.uuid] = _Button(int(max_bytes), on_file, on_refused, check)


def drop_client(client_id) -> None:
    """A tab closed: its uploads in flight (on any spooled GUI) are dropped and their files removed."""
    with _spools_lock:
        spools = list(_spools.values())
    for s in spools:
        s.drop_client(client_id)


def close(gui) -> None:
    """The GUI's app stops: its uploads in flight are dropped and their files removed."""
    with _spools_lock:
        s = _spools.pop(id(gui), None)
    if s is not None:
        s.close()
