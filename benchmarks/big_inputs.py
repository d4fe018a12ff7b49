"""Big inputs (issue 16): `rrbc correct` and `rrbc diagnose` on a million rows, as a user runs them.

Each command is a fresh process (`harness.run_command`: the caller's environment minus thread variables, peak
resident memory from /proc). The file: distinct points in an 800 x 600 x 500 mm volume, a large sensor->robot
rotation, a smooth robot bias (~0.3 mm), sensor noise 0.02 mm (`interactive._diagnose_file`); for `correct` the
first 50 rows are `both` (registration and fiducials) and the rest `check` rows, the heaviest case (every row is
corrected, scored and printed). Two sizes give the memory per row, to show the growth is linear.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from harness import RRBC, row, run_command
from interactive import _diagnose_file


def _as_checks(path: Path, n_both: int = 50) -> Path:
    """The same file with all rows but the first `n_both` turned into check rows."""
    out = path.with_name(path.stem + "_checks.csv")
    with open(path) as src, open(out, "w") as dst:
        k = -1
        for line in src:
            if line.startswith("#") or line.startswith("id,"):
                dst.write(line)
                continue
            k += 1
            dst.write(line if k < n_both else line.replace(",both,", ",check,", 1))
    return out


def big_inputs(quick: bool) -> list[dict]:
    """Time and peak memory of `rrbc correct FILE --json` (1e6 rows, 999 950 of them checks) and `rrbc diagnose
    FILE --json` (1e6 distinct paired points). Goals: each within 5 minutes and 4 GB on this 2-core, 24 GB machine
    (a million rows, the size issue 16 names as one a user would reasonably reach), memory linear in the rows."""
    sizes = (20_000, 100_000) if quick else (100_000, 1_000_000)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        files = {n: _diagnose_file(Path(tmp) / f"p{n}.csv", n, 707) for n in sizes}
        for name, make in (("correct", _as_checks), ("diagnose", lambda p: p)):
            seen = {}
            for n in sizes:
                seen[n] = run_command([RRBC, name, make(files[n]), "--json"], 1)[:2]
            big = sizes[-1]
            t, mb = seen[big]
            per_row = (seen[big][1] - seen[sizes[0]][1]) / (big - sizes[0]) * 1e6 / 1024  # GB per million rows
            rows.append(
                row(
                    f"{name}_{big}_rows",
                    t,
                    "s",
                    goal="< 300 s and < 4096 MB",
                    met=bool(t < 300 and mb < 4096),
                    note=f"`rrbc {name} FILE --json` as a fresh process: "
                    + ", ".join(f"{n:,} rows {s:.1f} s, peak {m:.0f} MB" for n, (s, m) in seen.items())
                    + f"; {per_row:.2f} GB more per million rows",
                )
            )
    return rows
