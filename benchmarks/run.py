"""Project benchmarks: `python benchmarks/run.py [--json] [--quick] [name ...]` (benchmarks/README.md).

Every benchmark is a function in BENCHMARKS that takes `quick` (bool) and returns rows (`harness.row`). Interactive
rows are measured twice, on an idle machine and with one busy core beside them; goals are judged on the loaded
figure. Nothing here sets a thread variable: the code runs as it does in a user's process.

With --json each row is printed as one JSON object per line and nothing else goes to stdout; without it, a
readable table. Names given on the command line select benchmarks by function name or row name.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))  # run from a checkout without installing

import big_inputs  # noqa: E402
import bounds_cost  # noqa: E402
import class_load  # noqa: E402
import gp_scale  # noqa: E402
import interactive  # noqa: E402
import montecarlo  # noqa: E402
import reproduce_speed  # noqa: E402
import startup  # noqa: E402
import threads_policy  # noqa: E402

BENCHMARKS = [
    montecarlo.mc_throughput_ls_rrbc,
    montecarlo.mc_throughput_annealing,
    threads_policy.mc_blas_threads,
    threads_policy.blas_pool_when_busy,
    interactive.drag_latency,
    class_load.class_load,
    interactive.suggest_app,
    interactive.plan_command,
    interactive.plan_optimiser,
    interactive.diagnose_command,
    interactive.calibrate_urdf,
    interactive.auto_interpolation,
    gp_scale.gp_scale,
    bounds_cost.correct_bounds,
    big_inputs.big_inputs,
    reproduce_speed.reproduce_speed,
    startup.startup,
]


def _num(x, unit: str) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    if unit == "s":
        return f"{x * 1e3:.1f} ms" if x < 1 else f"{x:.2f} s"
    return f"{x:.4g}"


def format_table(rows: list[dict]) -> str:
    head = f"{'benchmark':<30} {'idle':>11} {'busy core':>11} {'baseline':>11} {'unit':<9} {'ratio':>7}  goal"
    lines = [head, "-" * len(head)]
    for r in rows:
        ratio = "-" if r["ratio"] is None else f"{r['ratio']:.1f}x"
        goal = "" if r["goal"] is None else f"{r['goal']} ({'met' if r['met'] else 'NOT met'})"
        lines.append(
            f"{r['name']:<30} {_num(r['value'], r['unit']):>11} {_num(r['loaded'], r['unit']):>11} "
            f"{_num(r['baseline'], r['unit']):>11} {r['unit']:<9} {ratio:>7}  {goal}"
        )
    notes = [f"  {r['name']}: {r['note']}" for r in rows if r.get("note")]
    return "\n".join(lines + ([""] + notes if notes else []))


def write_report(path: Path, rows: list[dict], argv: list[str]) -> None:
    """The results as Markdown: the command, the machine, the table and each row's note (written whole)."""
    import datetime
    import os
    import platform

    import numpy

    command = "python benchmarks/run.py " + " ".join(argv)
    head = [
        "# Benchmarks",
        "",
        f"Made by `{command.strip()}` on {datetime.date.today().isoformat()}: {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, numpy {numpy.__version__}; no thread variables set. Numbers below "
        'are that run\'s (do not edit by hand); rows and their baselines: benchmarks/README.md. "busy core": the '
        "same measurement with one other process spinning on a core.",
        "",
        "```",
        format_table(rows),
        "```",
        "",
    ]
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text("\n".join(head))
    tmp.replace(path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="one JSON object per line, nothing else on stdout")
    parser.add_argument("--quick", action="store_true", help="fewer repeats and trials (a smoke run)")
    parser.add_argument(
        "--out",
        default=None,
        metavar="FILE",
        help="also write the results as a Markdown report (e.g. docs/benchmarks.md)",
    )
    parser.add_argument("names", nargs="*", help="run only these benchmarks (function or row names)")
    args = parser.parse_args(argv)
    functions = {fn.__name__ for fn in BENCHMARKS}
    by_row = [n for n in args.names if n not in functions]  # row names: run every benchmark, keep those rows
    selected = [fn for fn in BENCHMARKS if not args.names or by_row or fn.__name__ in args.names]
    stdout = sys.stdout
    rows = []
    for fn in selected:
        with contextlib.redirect_stdout(io.StringIO()):  # libraries' chatter never reaches the JSON stream
            produced = fn(args.quick)
        for r in produced:
            if args.names and fn.__name__ not in args.names and r["name"] not in args.names:
                continue
            rows.append(r)
            if args.json:
                print(json.dumps(r), file=stdout, flush=True)
    if not args.json:
        print(format_table(rows), file=stdout)
    if args.out:
        write_report(Path(args.out), rows, argv if argv is not None else sys.argv[1:])
    return 0 if all(r["met"] is not False for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
