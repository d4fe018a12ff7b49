"""One tab's uploads from a process of its own: `python -m tests.support.upload_client URL BUTTON NAME HEAD_HEX
SIZE` connects to the app at URL as viser's browser client does; for each number MARK it reads on a line of
its standard input it uploads through button BUTTON a file NAME of SIZE bytes in parts of 512 KiB, as
viser's browser client sends it (it starts with the bytes HEAD_HEX, the rest is random), then reports its camera's image 1280 + MARK pixels wide (a number the server never sets). It
closes when its input does. The server handles one connection's messages in the order they came, so a test that
sees that width knows the server has read every part; the server's memory measured in the test's process
holds none of the client's buffers (tests/viz/test_upload_spool.py)."""

from __future__ import annotations

import os
import sys

from tests.support.viser_clients import ClientPool, camera_message

CHUNK = 512 * 1024  # viser's browser client sends uploads in parts of this size


def main(argv: list[str]) -> None:
    url, button, name, head_hex, size_text = argv
    head, body, size = bytes.fromhex(head_hex), os.urandom(CHUNK), int(size_text)
    count = -(-size // CHUNK)

    def chunks():
        yield (head + body)[: min(CHUNK, size)]
        for i in range(1, count):
            yield body[: min(CHUNK, size - i * CHUNK)]

    pool = ClientPool(url, 1)
    try:
        for mark in sys.stdin:
            pool.upload(0, button, name, chunks(), size, count)
            pool.send_raw(0, camera_message(1280 + int(mark)))
    finally:
        pool.close()


if __name__ == "__main__":
    main(sys.argv[1:])
