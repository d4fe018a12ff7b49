"""Where the tests find the repository's files."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "scenes"
DEMO = SCENES / "demo_workcell.toml"
EXAMPLE_CSV = ROOT / "rrbc_core" / "data" / "example_measurements.csv"
#: The `rrbc` command of the interpreter running the tests, as an argument list.
RRBC = [str(Path(sys.executable).with_name("rrbc"))]
