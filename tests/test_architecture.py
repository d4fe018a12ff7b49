"""One-way dependencies: rrbc_viz -> rrbc_core; the core never imports viser (or the app).

The `rrbc` command lives in rrbc_core/cli.py; only its `view` subcommand imports rrbc_viz, lazily, when run."""

import subprocess
import sys

from tests.paths import ROOT

CORE = ROOT / "rrbc_core"


def test_importing_every_core_module_loads_neither_viser_nor_the_app():
    modules = sorted(
        ".".join(p.relative_to(CORE).with_suffix("").parts)
        for p in CORE.rglob("*.py")
        if p.stem != "__init__" and p.parent.name != "data"
    )
    code = (
        "import importlib, sys\n"
        f"for m in {modules!r}: importlib.import_module('rrbc_core.' + m)\n"
        "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('viser', 'rrbc_viz'))\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "", f"core imported: {out.stdout.strip()}"
    assert "cli" in modules and "session.explorer" in modules  # the test covers the modules that matter


def test_rrbc_correct_runs_without_loading_the_app(tmp_path):
    example = CORE / "data" / "example_measurements.csv"
    code = (
        "import sys\nfrom rrbc_core.cli import main\n"
        f"rc = main(['correct', {str(example)!r}, '--json'])\n"
        "bad = [m for m in sys.modules if m.split('.')[0] in ('viser', 'rrbc_viz')]\n"
        "sys.stderr.write('LOADED:' + ','.join(bad))\nsys.exit(rc)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stderr.strip().endswith("LOADED:")
