"""Real websocket clients of the app, as a class of browser tabs would be (issue 31): each connects to the page's
websocket address with the run's token and its own Origin, speaks viser 1.1.1's client protocol (msgpack messages
with a ``type`` field) and records when the server's messages arrive. A client can drag a handle (transform-control
start, updates at a rate, end), click a node, or send garbage.

Used by tests/viz/test_class_load.py (a bounded stress test) and benchmarks/class_load.py (20 clients, both modes).
Everything runs on one asyncio loop in a thread of its own (`ClientPool`), so a test's own loop is left alone.
"""

from __future__ import annotations

import asyncio
import threading
import time
from dataclasses import dataclass, field
from urllib.parse import parse_qs, urlsplit

import msgspec
import websockets

PROTOCOL = "viser-v1.1.1"


def websocket_address(page_url: str) -> tuple[str, str]:
    """(ws URL, Origin) of an app page URL as `rrbc view` prints it (`?websocket=` carries the token path)."""
    parts = urlsplit(page_url)
    origin = f"{parts.scheme}://{parts.netloc}"
    ws = parse_qs(parts.query).get("websocket", [f"ws://{parts.netloc}"])[0]
    return ws, origin


def encode(type_name: str, **fields) -> bytes:
    """One client message as viser's client sends it."""
    return msgspec.msgpack.encode({"type": type_name, **fields})


def camera_message(image_width: int = 1280) -> bytes:
    """A browser tab's camera report (`image_width` x 800 pixels, looking at the cell from -y)."""
    return encode(
        "ViewerCameraMessage",
        wxyz=[1.0, 0.0, 0.0, 0.0],
        position=[0.0, -2000.0, 1500.0],
        fov=0.87,
        near=0.1,
        far=100000.0,
        image_height=800,
        image_width=int(image_width),
        look_at=[450.0, 0.0, 0.0],
        up_direction=[0.0, 0.0, 1.0],
    )


@dataclass
class ClientRecord:
    """What one client saw: arrival times (time.monotonic) of the server's frames, and whether it was closed."""

    arrivals: list = field(default_factory=list)
    closed: bool = False
    close_code: int | None = None

    def gaps_between(self, t0: float, t1: float) -> float:
        """The longest stretch (s) within [t0, t1] without a frame from the server."""
        times = [t0] + [t for t in self.arrivals if t0 <= t <= t1] + [t1]
        return max(b - a for a, b in zip(times, times[1:]))

    def first_after(self, t: float) -> float | None:
        later = [a for a in self.arrivals if a > t]
        return min(later) - t if later else None


class ClientPool:
    """`n` clients of the app at `page_url`, on one event loop in a background thread (module docstring)."""

    def __init__(self, page_url: str, n: int, open_timeout: float = 30.0):
        self.ws_url, self.origin = websocket_address(page_url)
        self.records = [ClientRecord() for _ in range(n)]
        self._sockets: list = [None] * n
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="viser-clients", daemon=True)
        self._thread.start()
        self._readers: list = []
        self.run(self._connect_all(open_timeout), timeout=open_timeout + 30)

    def run(self, coro, timeout: float = 120.0):
        """Run `coro` on the clients' loop and wait for its result."""
        return asyncio.run_coroutine_threadsafe(coro, self._loop).result(timeout)

    async def _connect(self, k: int, open_timeout: float) -> None:
        ws = await websockets.connect(
            self.ws_url,
            subprotocols=[PROTOCOL],
            additional_headers={"Origin": self.origin},
            origin=None,
            open_timeout=open_timeout,
            max_size=None,
        )
        self._sockets[k] = ws
        self._readers.append(asyncio.ensure_future(self._read(k, ws)))
        # a browser reports its camera at once (the server waits for it before it frames the tab's view)
        await ws.send(camera_message())

    async def _connect_all(self, open_timeout: float) -> None:
        for k in range(len(self.records)):  # one after the other, as tabs are opened
            await self._connect(k, open_timeout)

    async def _read(self, k: int, ws) -> None:
        rec = self.records[k]
        try:
            async for _ in ws:
                rec.arrivals.append(time.monotonic())
        except websockets.exceptions.ConnectionClosed as exc:
            rec.close_code = exc.rcvd.code if exc.rcvd else None
        finally:
            rec.closed = True
            if rec.close_code is None and ws.close_code is not None:
                rec.close_code = ws.close_code

    async def _send(self, k: int, data: bytes) -> None:
        ws = self._sockets[k]
        if ws is not None and not self.records[k].closed:
            try:
                await ws.send(data)
            except websockets.exceptions.ConnectionClosed:
                pass

    def drag_all(self, handles, positions, seconds: float, rate_hz: float = 20.0, owners=None) -> tuple[float, float]:
        """Client k drags gizmo node `handles[k]` for `seconds`: a start, updates at `rate_hz` along
        `positions(k, t)` -> (3,), an end. `owners[k]`: the scope the node belongs to, as viser's client echoes it
        ("" the shared scene, str(client id) a tab's own scene). Returns (t0, t1): when the updates began and ended
        (time.monotonic)."""
        owners = [""] * len(handles) if owners is None else list(owners)

        async def one(k: int, t0: float) -> None:
            name, owner = handles[k], owners[k]
            await self._send(k, encode("TransformControlsDragStartMessage", name=name, owner=owner))
            step = 1.0 / rate_hz
            due = t0
            while (now := time.monotonic()) < t0 + seconds:
                p = [float(v) for v in positions(k, now - t0)]
                await self._send(
                    k,
                    encode(
                        "TransformControlsUpdateMessage", name=name, wxyz=[1.0, 0.0, 0.0, 0.0], position=p, owner=owner
                    ),
                )
                due += step
                await asyncio.sleep(max(0.0, due - time.monotonic()))
            await self._send(k, encode("TransformControlsDragEndMessage", name=name, owner=owner))

        async def all_() -> tuple[float, float]:
            t0 = time.monotonic() + 0.2
            await asyncio.sleep(0.2)
            await asyncio.gather(*(one(k, t0) for k in range(len(handles))))
            return t0, time.monotonic()

        return self.run(all_(), timeout=seconds + 60)

    def click(self, k: int, name: str, origin, direction, owner: str = "") -> float:
        """Client k clicks node `name` (a ray from `origin` along `direction`) of scope `owner`; returns when it was
        sent."""
        data = encode(
            "SceneNodeClickMessage",
            name=name,
            instance_index=None,
            ray_origin=[float(v) for v in origin],
            ray_direction=[float(v) for v in direction],
            screen_pos=[0.5, 0.5],
            modifier=None,
            owner=owner,
        )

        async def go() -> float:
            t = time.monotonic()
            await self._send(k, data)
            return t

        return self.run(go())

    def upload(
        self,
        k: int,
        button_uuid: str,
        name: str,
        parts,
        size_bytes: int,
        part_count: int,
        transfer_uuid: str | None = None,
    ) -> str:
        """Client k uploads a file through upload button `button_uuid` as viser's client does: a
        FileTransferStartUpload declaring `size_bytes` in `part_count` parts, then each of `parts` (an iterable of
        bytes, 512 KiB each but the last in viser's client; a test may send fewer or other ones). Returns the
        transfer's uuid."""
        import uuid as uuid_

        tid = transfer_uuid or str(uuid_.uuid4())

        async def go() -> None:
            await self._send(
                k,
                encode(
                    "FileTransferStartUpload",
                    source_component_uuid=button_uuid,
                    transfer_uuid=tid,
                    filename=name,
                    mime_type="application/octet-stream",
                    part_count=int(part_count),
                    size_bytes=int(size_bytes),
                ),
            )
            for i, content in enumerate(parts):
                await self._send(
                    k,
                    encode(
                        "FileTransferPart",
                        source_component_uuid=button_uuid,
                        transfer_uuid=tid,
                        part_index=i,
                        content=bytes(content),
                    ),
                )

        self.run(go(), timeout=600)
        return tid

    def send_raw(self, k: int, data: bytes) -> None:
        """Client k sends `data` as one binary message (garbage, or a wrongly typed message)."""
        self.run(self._send(k, data))

    def close(self) -> None:
        async def shut() -> None:
            for ws in self._sockets:
                if ws is not None:
                    try:
                        await asyncio.wait_for(ws.close(), 5)
                    except Exception:  # noqa: BLE001 - already gone
                        pass
            for r in self._readers:
                r.cancel()

        try:
            self.run(shut(), timeout=30)
        finally:
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(10)
            self._sockets = [None] * len(self._sockets)  # the connections and their buffers go (the records stay)
            self._readers = []
            self._loop.close()
