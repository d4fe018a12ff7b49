"""Bad days for the command line's writers (issue 31, item 5): a full disk gives one line and exit 2 with nothing
written, and a writer killed mid-run leaves either no file or a whole one at its destination (every writer goes
through `io.measurements_write.atomic_write_text`: a hidden temporary file beside the destination, then a rename)."""

from __future__ import annotations

import errno
import os
import signal
import subprocess
import time

import pytest

from rrbc_core.cli import main
from rrbc_core.io import measurements_write
from rrbc_core.io.measurements import read_measurements
from rrbc_core.io.scene import default_scene_path
from tests.paths import EXAMPLE_CSV, RRBC


def _no_space(*args, **kwargs):
    raise OSError(errno.ENOSPC, "No space left on device")


@pytest.mark.parametrize(
    "make",
    [
        lambda d: ["simulate", str(default_scene_path()), "--trials", "2", "--out", str(d / "out.csv")],
        lambda d: ["convert", str(EXAMPLE_CSV), "--to", "slicer", "--out", str(d)],
        lambda d: ["calibrate", str(d / "arm.csv"), "--urdf", "lift_arm", "--save-model", str(d / "m.json")],
    ],
    ids=["simulate --out", "convert --to slicer", "calibrate --save-model"],
)
def test_a_full_disk_gives_one_line_exit_2_and_nothing_written(tmp_path, monkeypatch, capsys, make):
    if "calibrate" in make(tmp_path)[0]:
        from rrbc_core.models.urdf import load_urdf
        from rrbc_core.simulation.arm_data import chain_measurements

        measurements_write.write_measurements(
            tmp_path / "arm.csv", chain_measurements(load_urdf("lift_arm"), 1, n_fid=20, n_chk=4)
        )
    before = set(os.listdir(tmp_path))
    monkeypatch.setattr(measurements_write.os, "replace", _no_space)
    assert main(make(tmp_path)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "No space left on device" in err[0] and "Traceback" not in err[0], err
    assert set(os.listdir(tmp_path)) == before  # neither the file nor its temporary copy


@pytest.mark.slow
def test_a_writer_killed_mid_run_leaves_no_partial_file(tmp_path):
    """`rrbc simulate --out` killed (SIGKILL) at several moments of its run: the destination is absent or whole."""
    dest = tmp_path / "out.csv"
    args = [*RRBC, "simulate", str(default_scene_path()), "--trials", "20", "--out", str(dest)]
    start = time.monotonic()
    full = subprocess.run(args, capture_output=True, text=True, timeout=600)
    assert full.returncode == 0, full.stderr
    whole = dest.read_text()
    took = time.monotonic() - start
    dest.unlink()
    for fraction in (0.3, 0.6, 0.8, 0.9, 0.97):
        p = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(fraction * took)
        p.send_signal(signal.SIGKILL)
        p.wait(30)
        if dest.exists():  # the rename happened before the kill: the file is whole
            assert dest.read_text() == whole, fraction
            read_measurements(dest)
            dest.unlink()
        visible = [q.name for q in tmp_path.iterdir() if not q.name.startswith(".")]
        assert visible == [], (fraction, visible)  # nothing half-written under a name a user would open
        for q in tmp_path.iterdir():  # a hidden temporary copy the kill left behind
            q.unlink()


def _fails_after_the_first_piece(real):
    def broken(obj):
        pieces = real(obj)
        yield next(pieces)
        raise RuntimeError("a planted failure while the JSON is written")

    return broken


@pytest.mark.parametrize("before", ["", "a line the shell wrote first\n"])
def test_a_json_that_fails_while_written_to_a_file_leaves_none_of_it(tmp_path, monkeypatch, capsys, before):
    """`rrbc correct --json > out.json` that fails midway (issue 42): one line on stderr, exit 1, and the file cut back
    to where the command's output began (what was there before is kept)."""
    import sys

    from rrbc_core.io import json_stream

    monkeypatch.setattr(json_stream, "CHUNK_CHARS", 64)  # many pieces even for the example file
    monkeypatch.setattr(json_stream, "json_bytes", _fails_after_the_first_piece(json_stream.json_bytes))
    out = tmp_path / "out.json"
    with open(out, "w", encoding="utf-8") as f:
        f.write(before)
        monkeypatch.setattr(sys, "stdout", f)
        rc = main(["correct", str(EXAMPLE_CSV), "--json"])
        monkeypatch.undo()
    assert rc == 1
    assert out.read_text(encoding="utf-8") == before
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a planted failure" in err, err


def test_a_json_that_fails_while_written_to_a_pipe_is_never_valid_json(tmp_path):
    """Through a pipe what was sent stays sent; the exit code says it failed, and the text is a strict prefix of one
    JSON object, which no parser accepts."""
    import json
    import sys

    code = (
        "import sys; from rrbc_core.io import json_stream as js; from rrbc_core.cli import main; real = js.json_bytes\n"
        "def broken(obj):\n    p = real(obj); yield next(p); raise RuntimeError('planted')\n"
        f"js.CHUNK_CHARS = 64; js.json_bytes = broken; sys.exit(main(['correct', {str(EXAMPLE_CSV)!r}, '--json']))\n"
    )
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert p.returncode == 1 and p.stdout.startswith("{") and len(p.stdout) >= 64, (p.returncode, p.stdout[:80])
    with pytest.raises(json.JSONDecodeError):
        json.loads(p.stdout)
    assert p.stderr.count("\n") == 1 and "planted" in p.stderr, p.stderr
