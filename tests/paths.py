"""Where the tests find the repository's files."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "scenes"
DEMO = SCENES / "demo_workcell.toml"
EXAMPLE_CSV = ROOT / "rrbc_core" / "data" / "example_measurements.csv"
