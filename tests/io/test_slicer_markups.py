"""Measurement files <-> 3D Slicer markups (rrbc_core.io.slicer_markups, `rrbc convert`): exact round trips, RAS
read as Slicer converts it, refusals in one line."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest

from rrbc_core.errors import InputError
from rrbc_core.io.measurements import read_measurements
from rrbc_core.io.slicer_markups import read_markups, to_markups
from tests.paths import EXAMPLE_CSV, RRBC


def test_round_trip_through_the_command_is_exact(tmp_path):
    src = read_measurements(EXAMPLE_CSV)
    r = subprocess.run(
        [*RRBC, "convert", str(EXAMPLE_CSV), "--to", "slicer", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 0, r.stderr
    stem = EXAMPLE_CSV.name[:-4]
    s_path, r_path = tmp_path / f"{stem}_sensor.mrk.json", tmp_path / f"{stem}_robot.mrk.json"
    doc = json.loads(s_path.read_text())
    m = doc["markups"][0]
    assert m["coordinateUnits"] == "mm" and m["type"] == "Fiducial"
    assert [p["label"] for p in m["controlPoints"]] == list(src.ids)
    back = tmp_path / "back.csv"
    r = subprocess.run(
        [*RRBC, "convert", str(s_path), str(r_path), "--to", "csv", "--out", str(back)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 0, r.stderr
    got = read_measurements(back)
    assert got.ids == src.ids and got.roles == src.roles
    np.testing.assert_allclose(got.sensor, src.sensor, atol=1e-6, rtol=0)
    np.testing.assert_allclose(got.robot, src.robot, atol=1e-6, rtol=0, equal_nan=True)
    np.testing.assert_allclose(got.time, src.time, atol=1e-9, equal_nan=True)


def test_ras_is_read_as_slicer_converts_it_and_bad_files_are_refused(tmp_path):
    src = read_measurements(EXAMPLE_CSV)
    sensor, robot = to_markups(src)
    for doc in (sensor, robot):
        doc["markups"][0]["coordinateSystem"] = "RAS"
        for p in doc["markups"][0]["controlPoints"]:
            p["position"] = [-p["position"][0], -p["position"][1], p["position"][2]]
    (tmp_path / "s.mrk.json").write_text(json.dumps(sensor))
    (tmp_path / "r.mrk.json").write_text(json.dumps(robot))
    got = read_markups(tmp_path / "s.mrk.json", tmp_path / "r.mrk.json")
    np.testing.assert_allclose(got.sensor, src.sensor, atol=1e-9)
    # a fiducial without its robot point
    fid = next(i for i, role in enumerate(src.roles) if role == "fiducial")
    robot["markups"][0]["controlPoints"] = [
        p for p in robot["markups"][0]["controlPoints"] if p["label"] != src.ids[fid]
    ]
    (tmp_path / "r2.mrk.json").write_text(json.dumps(robot))
    with pytest.raises(InputError, match="must follow the sensor list|no robot point"):
        read_markups(tmp_path / "s.mrk.json", tmp_path / "r2.mrk.json")
    (tmp_path / "bad.mrk.json").write_text("{not json")
    with pytest.raises(InputError, match="not a JSON file"):
        read_markups(tmp_path / "bad.mrk.json", tmp_path / "r.mrk.json")
    r = subprocess.run(
        [
            *RRBC,
            "convert",
            str(tmp_path / "bad.mrk.json"),
            str(tmp_path / "r.mrk.json"),
            "--to",
            "csv",
            "--out",
            str(tmp_path / "x.csv"),
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "x.csv").exists()


def test_an_out_folder_that_does_not_exist_yet_is_created(tmp_path):
    """Issue 40: every `--out DIR` creates the folder (with its missing parents); under a file it is refused."""
    out = tmp_path / "new" / "markups"
    r = subprocess.run(
        [*RRBC, "convert", str(EXAMPLE_CSV), "--to", "slicer", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in out.iterdir()) == [
        f"{EXAMPLE_CSV.name[:-4]}_robot.mrk.json",
        f"{EXAMPLE_CSV.name[:-4]}_sensor.mrk.json",
    ]
    (tmp_path / "file").write_text("x")
    r = subprocess.run(
        [*RRBC, "convert", str(EXAMPLE_CSV), "--to", "slicer", "--out", str(tmp_path / "file" / "below")],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
