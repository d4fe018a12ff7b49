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


def test_printable_output_keeps_lines_and_tabs_and_escapes_the_rest():
    from rrbc_core.errors import printable

    assert printable("a\x1b[31mb\nc\td\x00") == "a\\x1b[31mb\nc\td\\x00"


def test_an_id_with_ansi_escapes_is_printed_escaped_in_tables(tmp_path):
    rows = [
        "id,role,sensor_x,sensor_y,sensor_z,robot_x,robot_y,robot_z",
        "R1,both,0,0,0,0,0,0",
        "R2,both,100,0,0,100,0,0",
        "R3,both,0,100,0,0,100,0",
        "R4,both,0,0,100,0,0,100",
        "\x1b[2JT1,target,50,50,50,,,",
    ]
    path = tmp_path / "m.csv"
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    r = subprocess.run([*RRBC, "correct", str(path)], capture_output=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert b"\x1b" not in r.stdout and b"\\x1b[2JT1" in r.stdout


def test_huge_scene_and_error_model_numbers_are_one_line(tmp_path):
    from tests.paths import SCENES

    text = (SCENES / "demo_workcell.toml").read_text(encoding="utf-8")
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "demo_workcell.glb").write_bytes((SCENES / "meshes" / "demo_workcell.glb").read_bytes())
    for old, new in (("sigma_mm = 0.03", "sigma_mm = 1e300"), ("[1100.0, -450.0, 1250.0]", "[1e300, -450.0, 1250.0]")):
        path = tmp_path / "s.toml"
        path.write_text(text.replace(old, new, 1), encoding="utf-8")
        r = subprocess.run([*RRBC, "plan", str(path)], capture_output=True, text=True, timeout=120)
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert "at most" in r.stderr


def test_a_huge_time_in_diagnose_is_one_line(tmp_path):
    rows = ["id,role,sensor_x,sensor_y,sensor_z,robot_x,robot_y,robot_z,time"]
    for i, (x, y, z) in enumerate([(0, 0, 0), (100, 0, 0), (0, 100, 0), (0, 0, 100), (50, 50, 50), (80, 20, 10)]):
        rows.append(f"P{i},both,{x},{y},{z},{x},{y},{z},{1e300 if i == 3 else i}")
    path = tmp_path / "t.csv"
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    r = subprocess.run([*RRBC, "diagnose", str(path)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "line 5" in r.stderr and "time" in r.stderr and "out of range" in r.stderr


def test_a_mesh_that_is_a_loop_of_symbolic_links_is_named_as_one(tmp_path):
    from tests.paths import ROOT

    text = (ROOT / "scenes" / "demo_workcell.toml").read_text(encoding="utf-8")
    (tmp_path / "s.toml").write_text(text.replace('"meshes/demo_workcell.glb"', '"loop.glb"'), encoding="utf-8")
    (tmp_path / "loop.glb").symlink_to(tmp_path / "loop.glb")
    p = subprocess.run([*RRBC, "plan", str(tmp_path / "s.toml")], capture_output=True, text=True, timeout=60)
    assert p.returncode == 2 and p.stdout == ""
    assert p.stderr.count("\n") == 1 and "a loop of symbolic links" in p.stderr
