"""Hostile input, tried as a hostile user would (issue 16): malformed measurement files and scenes through the real
commands, each judged against the command line's contract (docs/cli.md):

- bad input: exit 2, nothing on stdout, exactly one line on stderr starting ``rrbc: error:``, at most 400
  characters of message, no control characters, no traceback;
- accepted input: exit 0 and nothing on stderr (no numpy warnings);
- never exit 1 (an internal error) and never a run longer than ``--timeout`` seconds.

Usage::

    .venv/bin/python scripts/hostile_probe.py                 # every named case + 100 random ones, fresh processes
    .venv/bin/python scripts/hostile_probe.py --in-process    # the same through rrbc_core.cli.main (fast)
    .venv/bin/python scripts/hostile_probe.py --random 0 --json

Prints one line per broken contract and a summary (``--json``: one object); the exit status is 1 when any contract
was broken. Measurement files go through `correct`, `diagnose` and `calibrate`; scenes through `plan` and
`simulate --trials 5`.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

EXAMPLE = ROOT / "rrbc_core" / "data" / "example_measurements.csv"
SCENE = ROOT / "scenes" / "demo_workcell.toml"
MEASUREMENT_COMMANDS = (["correct"], ["diagnose"], ["calibrate"])
SCENE_COMMANDS = (["plan"], ["simulate", "--trials", "5"])
RRBC = str(Path(sys.executable).with_name("rrbc"))
CONTROL = {chr(c) for c in range(32) if chr(c) not in "\n\t"} | {chr(c) for c in range(0x7F, 0xA0)}


# ------------------------------------------------------------------------------------------------ the cases
def _csv_rows(text: str) -> tuple[list[str], list[str]]:
    lines = text.splitlines()
    head = [ln for ln in lines if ln.startswith("#")]
    body = [ln for ln in lines if not ln.startswith("#")]
    return head, body


def measurement_cases() -> dict[str, bytes]:
    """Named malformed (and a few odd but valid) measurement files."""
    text = EXAMPLE.read_text(encoding="utf-8")
    _, body = _csv_rows(text)
    header, rows = body[0], body[1:]
    cells = [r.split(",") for r in rows]

    def join(hdr: str, rs) -> bytes:
        return ("\n".join([hdr] + [",".join(r) if isinstance(r, list) else r for r in rs]) + "\n").encode()

    def with_cell(i: int, col: int, value: str) -> bytes:
        rs = [list(c) for c in cells]
        rs[i][col] = value
        return join(header, rs)

    cases = {
        "empty": b"",
        "header only": (header + "\n").encode(),
        "comments only": b"# nothing\n# here\n",
        "BOM": b"\xef\xbb\xbf" + text.encode(),
        "CRLF": text.replace("\n", "\r\n").encode(),
        "missing robot_z column": join(header.replace(",robot_z", ""), [",".join(c[:7] + c[8:]) for c in cells]),
        "column named twice": join(header.replace("robot_z", "robot_y"), cells),
        "binary junk": bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8)),
        "not UTF-8": text.encode("utf-8").replace(b"grid", b"gr\xffid", 1),
        "NUL bytes": text.replace("F12", "F\x0012", 1).encode(),
        "ANSI escape in id": text.replace("F12", "F\x1b[31mRED\x1b[0m", 1).encode(),
        "5 KB line": join(header, cells[:3] + [["x" * 5000] * 10] + cells[3:]),
        "extra cells": join(header, [c + ["1"] for c in cells]),
        "missing cells": join(header, [c[:5] for c in cells]),
        "unknown role": with_cell(0, 1, "fidcuial"),
        "unterminated quote": join(header, cells[:2] + ['F99,"both,1,2,3,4,5,6,7,x'] + cells[2:]),
        "id empty": with_cell(1, 0, ""),
        "id 10 000 characters": with_cell(1, 0, "A" * 10_000),
        "1000 cells": join(header, cells[:1] + [",".join(["1"] * 1000)] + cells[1:]),
        "only targets": join(header, [[c[0], "target"] + c[2:] for c in cells]),
        "same id two roles": join(header, cells + [[cells[1][0], "target"] + cells[1][2:]]),
        "registration coincident": join(
            header, [c if c[1] != "both" else [c[0], "both"] + cells[0][2:] for c in cells]
        ),
    }
    for token in ("abc", "nan", "inf", "-inf", "Infinity", "+inf", "1e300", "1e155", "-1e10", "0x1p3", "1_000",
                  " 1.0", "\u0663\u0661", "\uff11\uff12", "1,5", "--1", "1e", ""):  # fmt: skip
        cases[f"sensor_x = {token!r}"] = with_cell(2, 2, token.replace(",", "."))
    for token in ("1e300", "-1e15", "nan", "abc"):
        cases[f"time = {token!r}"] = with_cell(2, 8, token)
    # joint columns: partial, radians, non-numeric
    hdr_q = header + ",q1,q2,q3"
    cases["partial joint columns"] = join(hdr_q, [c + ["10", "20", "30"] for c in cells])
    hdr_q6 = header + ",q1,q2,q3,q4,q5,q6"
    cases["joints in radians"] = join(hdr_q6, [c + ["0.1", "-1.2", "1.0", "-1.5", "-1.57", "0.3"] for c in cells])
    cases["joint not a number"] = join(hdr_q6, [c + ["x", "1", "2", "3", "4", "5"] for c in cells])
    return cases


def random_measurement_cases(n: int, seed: int) -> dict[str, bytes]:
    """`n` seeded mutations of the example file: a random cell replaced by a hostile token, a row dropped or
    duplicated, or a random byte changed."""
    rng = np.random.default_rng(seed)
    text = EXAMPLE.read_text(encoding="utf-8")
    lines = text.splitlines()
    tokens = ["", "x", "nan", "inf", "1e308", "-1e308", "1e-320", "\x00", "\x1b[2J", "\u202e", "'", '"', "both",
              "target", "check", "registration", "9" * 400, "-0", "1e9", "1e10", "\u0660", "\t"]  # fmt: skip
    out = {}
    for k in range(n):
        ls = list(lines)
        kind = int(rng.integers(4))
        data_idx = [i for i, ln in enumerate(ls) if ln and not ln.startswith("#")][1:]
        i = int(rng.choice(data_idx))
        if kind == 0:
            cells = ls[i].split(",")
            cells[int(rng.integers(len(cells)))] = str(rng.choice(tokens))
            ls[i] = ",".join(cells)
            data = ("\n".join(ls) + "\n").encode()
        elif kind == 1:
            del ls[i]
            data = ("\n".join(ls) + "\n").encode()
        elif kind == 2:
            ls.insert(i, ls[i])
            data = ("\n".join(ls) + "\n").encode()
        else:
            b = bytearray(("\n".join(ls) + "\n").encode())
            b[int(rng.integers(len(b)))] = int(rng.integers(256))
            data = bytes(b)
        out[f"random {k} (kind {kind})"] = data
    return out


def scene_cases() -> dict[str, str]:
    """Named malformed scenes (text of a TOML file placed beside a copy of the scenes' meshes)."""
    s = SCENE.read_text(encoding="utf-8")
    first_pos = s[s.index("position = [", s.index("[[registration]]")) :].split("\n", 1)[0]
    return {
        "empty": "",
        "not TOML": "[scene\nname = ",
        "BOM": "\ufeff" + s,
        "nested 5000 deep": "a = " + "[" * 5000 + "]" * 5000 + "\n",
        "no [scene]": s.replace("[scene]", "[scenery]", 1),
        "position a string": s.replace(first_pos, 'position = "here"', 1),
        "position two numbers": s.replace(first_pos, "position = [1.0, 2.0]", 1),
        "position 1e300": s.replace(first_pos, "position = [1e300, 0.0, 0.0]", 1),
        "position nan": s.replace(first_pos, "position = [nan, 0.0, 0.0]", 1),
        "position out of reach": s.replace(first_pos, "position = [5000.0, 0.0, 0.0]", 1),
        "mesh escapes the folder": s.replace('mesh = "meshes/demo_workcell.glb"', 'mesh = "../../../etc/passwd"'),
        "mesh absolute": s.replace('mesh = "meshes/demo_workcell.glb"', 'mesh = "/etc/shadow"'),
        "mesh missing": s.replace('mesh = "meshes/demo_workcell.glb"', 'mesh = "meshes/none.glb"'),
        "mesh symlink loop": s.replace('mesh = "meshes/demo_workcell.glb"', 'mesh = "loop.glb"'),
        "check points 1e9": s.replace("check_points_per_target = 20", "check_points_per_target = 1000000000"),
        "sigma 1e300": s.replace("sigma_mm = ", "sigma_mm = 1e300 # ", 1),
        "unknown error term": s.replace('type = "', 'type = "no_such_', 1),
        "id twice": s.replace('id = "R2"', 'id = "R1"', 1),
        "ANSI in name": s.replace('name = "', 'name = "\\u001b[31m', 1),
    }


# ------------------------------------------------------------------------------------------------ running
def _run_process(args: list[str], timeout: float) -> tuple[int, str, str, float]:
    env = {k: v for k, v in os.environ.items() if k != "RRBC_DEBUG"}
    t0 = time.perf_counter()
    try:
        p = subprocess.run([RRBC, *args], capture_output=True, timeout=timeout, env=env, stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        return -1, "", "", time.perf_counter() - t0
    return (
        p.returncode,
        p.stdout.decode("utf-8", "replace"),
        p.stderr.decode("utf-8", "replace"),
        (time.perf_counter() - t0),
    )


def _run_in_process(args: list[str], timeout: float) -> tuple[int, str, str, float]:
    import warnings

    from rrbc_core.cli import main

    out, err = io.StringIO(), io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), warnings.catch_warnings():
        warnings.simplefilter("always")  # a warning a fresh process would print must show here too
        code = main(args)
    return code, out.getvalue(), err.getvalue(), time.perf_counter() - t0


def judge(code: int, out: str, err: str, seconds: float, timeout: float) -> str | None:
    """None when the run kept the contract, else what it broke."""
    if code == -1 or seconds > timeout:
        return f"ran longer than {timeout:.0f} s"
    if code == 0:
        return None if err == "" else f"exit 0 but stderr {err[:120]!r}"
    if code != 2:
        return f"exit {code}: {err.strip()[:200]!r}"
    lines = err.splitlines()
    if out:
        return "exit 2 with output on stdout"
    if len(lines) != 1:
        return f"exit 2 with {len(lines)} stderr lines: {err[:200]!r}"
    if not lines[0].startswith("rrbc: error:") or "Traceback" in err:
        return f"exit 2, odd stderr line {lines[0][:200]!r}"
    if len(lines[0]) > 420:
        return f"stderr line of {len(lines[0])} characters"
    if any(ch in CONTROL for ch in lines[0]):
        return "control characters on stderr"
    return None


def _tally(results: dict, run, args: list[str], timeout: float, case: str, log) -> None:
    code, out, err, sec = run(args, timeout)
    results["runs"] += 1
    results[f"exit_{code}"] = results.get(f"exit_{code}", 0) + 1
    broken = judge(code, out, err, sec, timeout)
    if broken:
        results["broken"].append({"case": case, "command": args[0], "what": broken})
        log(f"BROKEN {args[0]} on {case!r}: {broken}")


def probe(in_process: bool, n_random: int, seed: int, timeout: float, log=print) -> dict:
    run = _run_in_process if in_process else _run_process
    results = {"runs": 0, "exit_0": 0, "exit_2": 0, "broken": []}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        files = {**measurement_cases(), **random_measurement_cases(n_random, seed)}
        for k, (name, data) in enumerate(files.items()):
            path = tmp / f"m{k}.csv"
            path.write_bytes(data)
            for cmd in MEASUREMENT_COMMANDS:
                _tally(results, run, [*cmd, str(path)], timeout, name, log)
        shutil.copytree(ROOT / "scenes" / "meshes", tmp / "meshes")
        os.symlink(tmp / "loop.glb", tmp / "loop.glb")
        for k, (name, text) in enumerate(scene_cases().items()):
            path = tmp / f"s{k}.toml"
            path.write_text(text, encoding="utf-8")
            for cmd in SCENE_COMMANDS:
                _tally(results, run, [cmd[0], str(path), *cmd[1:]], timeout, f"scene {name}", log)
    return results


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--in-process", action="store_true", help="call rrbc_core.cli.main instead of processes")
    parser.add_argument("--random", type=int, default=100, help="seeded random mutations of the example file")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--timeout", type=float, default=120.0, help="seconds one run may take")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    res = probe(args.in_process, args.random, args.seed, args.timeout, log=(lambda s: None) if args.json else print)
    if args.json:
        print(json.dumps(res))
    else:
        print(
            f"{res['runs']} runs: {res['exit_0']} accepted, {res['exit_2']} refused with one line, "
            f"{len(res['broken'])} broke the contract"
        )
    return 1 if res["broken"] else 0


if __name__ == "__main__":
    sys.exit(main())
