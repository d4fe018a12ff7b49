"""Planted-model recovery on the CRPI layout (issue 17): how often `rrbc reproduce crpi`'s selection names what was
planted. For each planted kind (per-site offsets, a smooth field, a UR5 kinematic field; seeded random sizes,
`crpi_models.planted_sites`) it simulates SETS data sets of this exact layout and prints, as a Markdown table, the
family each selection claimed.

    .venv/bin/python scripts/crpi_recovery.py [--sets 100] [--seed 5000]
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from rrbc_core.studies import crpi_models

FAMILIES = ("seating", "smooth", "kinematic", "other")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sets", type=int, default=100)
    parser.add_argument("--seed", type=int, default=5000)
    args = parser.parse_args(argv)
    print(f"Made by `python scripts/crpi_recovery.py --sets {args.sets} --seed {args.seed}`.\n")
    print("| planted | " + " | ".join(f"named {f}" for f in FAMILIES) + " | right |")
    print("|---" * (len(FAMILIES) + 2) + "|")
    for k, kind in enumerate(crpi_models.PLANTED):
        chosen = crpi_models.recovery(kind, args.sets, args.seed + 100_000 * k)
        fam = Counter(crpi_models.named_family(c) for c in chosen)
        cells = " | ".join(str(fam.get(f, 0)) for f in FAMILIES)
        print(f"| {kind} | {cells} | {fam.get(kind, 0)}/{args.sets} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
