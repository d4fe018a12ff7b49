"""Messages shown to a user are one safe line (issue 16): control characters escaped, length capped, file content
quoted only as a short excerpt."""

import subprocess

from rrbc_core.errors import MESSAGE_LIMIT, excerpt, one_line
from tests.paths import RRBC


def test_one_line_escapes_control_characters_and_caps_the_length():
    assert one_line("a\x1b[31mb\x00c\x7fd\x9be") == "a\\x1b[31mb\\x00c\\x7fd\\x9be"
    assert one_line("two\nlines\r\n  here") == "two lines here"
    long = one_line("x" * 10_000)
    assert len(long) == MESSAGE_LIMIT and long.endswith("…")
    assert excerpt("root:x:0:0:root:/root:/bin/bash", 12) == "root:x:0:0:…"


def test_a_file_full_of_escapes_and_nuls_gives_one_short_safe_line(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_bytes(b"id,role,sensor_x\x1b[2J\x1b[31m" + b"\x00" * 5000 + b"\n")
    r = subprocess.run([*RRBC, "correct", str(bad)], capture_output=True, timeout=60)
    err = r.stderr.decode("utf-8")
    assert r.returncode == 2 and len(err.strip().splitlines()) == 1
    assert "\x1b" not in err and "\x00" not in err and len(err) < MESSAGE_LIMIT + 40
