"""A command's start-up (issue 41, item 4): the parser of every subcommand, `--help` and a refused flag load
neither scipy (the interpolators import it where they compute) nor the thread controller (the process policy is
applied once the arguments are parsed); `benchmarks/startup.py` measures the time."""

from __future__ import annotations

import subprocess
import sys

HEAVY = ("scipy", "threadpoolctl", "matplotlib", "trimesh", "viser")

PROBE = """
import sys
from rrbc_core.cli import build_parser, main
subcommands = [a for a in build_parser()._subparsers._group_actions[0].choices]
codes = []
for argv in [["--help"]] + [[s, "--help"] for s in subcommands]:
    try:
        main(argv)
    except SystemExit as exc:
        codes.append(exc.code)
codes.append(main(["correct", "no-such.csv", "--no-such-flag"]))
heavy = sorted(m for m in sys.modules if any(m == h or m.startswith(h + ".") for h in HEAVY))
print(len(subcommands), codes.count(0), codes[-1], heavy)
"""


def test_help_and_a_bad_flag_load_no_heavy_library():
    out = subprocess.run(
        [sys.executable, "-c", f"HEAVY = {HEAVY!r}\n" + PROBE], capture_output=True, text=True, check=True
    )
    n, helped, bad, heavy = out.stdout.strip().splitlines()[-1].split(" ", 3)
    assert int(n) >= 10 and int(helped) == int(n) + 1  # every subcommand's --help exits 0
    assert bad == "2" and heavy == "[]", out.stdout[-500:]


def test_diagnose_and_correct_do_not_import_scipy_stats(tmp_path):
    """scipy.stats costs about a second to import (its distributions' documentation is built on import): `rrbc
    diagnose` and `rrbc correct` take the few tails and quantiles they need from scipy.special, which computes them
    the same way (issue 41: a 1000-point diagnosis under 1.5 s)."""
    from tests.paths import EXAMPLE_CSV

    probe = (
        "import sys\n"
        "from rrbc_core.cli import main\n"
        f"main(['diagnose', {str(EXAMPLE_CSV)!r}, '--json'])\n"
        f"main(['correct', {str(EXAMPLE_CSV)!r}, '--json'])\n"
        "print('scipy.stats' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True, cwd=tmp_path)
    assert out.stdout.strip().splitlines()[-1] == "False", out.stdout[-300:]
