"""The `rrbc` command line (contract: shared/spec/cli.md). A thin layer over the core.

Exit status: 0 success; 2 bad input or usage (one line on stderr, nothing on stdout); 1 unexpected internal
error (one line on stderr; set RRBC_DEBUG=1 for the traceback). Output is built completely before anything is
printed, so a failure never leaves partial output.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

from .errors import InputError


class _UsageError(Exception):
    pass


class _Parser(argparse.ArgumentParser):
    """argparse that reports usage errors as one line (exit 2) instead of a usage block."""

    def error(self, message):
        raise _UsageError(f"{self.prog}: {message} (see '{self.prog} --help')")


def _positive_int(text):
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not an integer") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {v}")
    return v


def _positive_float(text):
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
    if not v > 0 or v == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return v


def build_parser() -> argparse.ArgumentParser:
    from . import interpolation, registration

    p = _Parser(prog="rrbc", description="Restoration of Rigid-Body Condition (RRBC): registration and corrections")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    c = sub.add_parser("correct", help="run RRBC on a measurement file", description="Run RRBC on a measurement file.")
    c.add_argument("measurements", help="measurement CSV (shared/spec/measurement-file.md)")
    c.add_argument("--registration", default="least-squares", choices=list(registration.STRATEGIES))
    c.add_argument("--interpolation", default="idw", choices=list(interpolation.METHODS))
    c.add_argument("--neighbors", type=_positive_int, default=None, help="IDW: number of nearest fiducials (default 4)")
    c.add_argument("--power", type=_positive_float, default=None, help="IDW: weight exponent p in 1/d^p (default 2)")
    c.add_argument("--seed", type=int, default=0, help="seed for annealing and clustering (default 0)")
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.set_defaults(run=_cmd_correct)
    return p


def _fmt_vec(v, width=9, prec=4):
    return " ".join(f"{x:{width}.{prec}f}" for x in v)


def _table(result) -> str:
    import numpy as np

    reg = result.registration
    lines = []
    m = reg.mapping.as_dict()
    lines.append(f"registration: {reg.method}   FRE {reg.fre_rms_mm:.4f} mm (RMS over {len(reg.residuals)} points)")
    if m.get("piecewise"):
        lines.append(f"  piecewise: {len(m['pieces'])} clusters, each point uses its nearest kernel")
        for k, pc in enumerate(m["pieces"]):
            lines.append(f"  kernel {k}: [{_fmt_vec(pc['kernel'], 9, 2)}]  translation [{_fmt_vec(pc['translation'], 10, 4)}]")
    else:
        for k in range(3):
            label = "  rotation    " if k == 0 else "              "
            lines.append(f"{label}[{_fmt_vec(m['rotation'][k], 10, 7)}]")
        lines.append(f"  translation [{_fmt_vec(m['translation'], 10, 4)}] mm")
    interp = result.to_json()["interpolation"]
    opts = ", ".join(f"{k}={v}" for k, v in interp.items() if k != "method")
    lines.append(f"interpolation: {interp['method']}" + (f" ({opts})" if opts else ""))
    lines.append("")
    lines.append(f"fiducials ({len(result.fiducials.ids)}): correction e = R^T(b - t) - s, sensor frame, mm")
    lines.append(f"  {'id':<12} {'e_x':>9} {'e_y':>9} {'e_z':>9} {'|e|':>9}")
    for pid, e in zip(result.fiducials.ids, result.fiducial_corrections):
        lines.append(f"  {pid:<12} {_fmt_vec(e)} {np.linalg.norm(e):9.4f}")
    for title, group, cp, checks in (
        ("targets", result.targets, result.targets_corrected, False),
        ("checks", result.checks, result.checks_corrected, True),
    ):
        if cp is None:
            continue
        lines.append("")
        head = f"  {'id':<12} {'corr_x':>9} {'corr_y':>9} {'corr_z':>9}   {'robot_rrbc_x':>12} {'robot_rrbc_y':>12} {'robot_rrbc_z':>12}"
        if checks:
            head += f" {'err_rigid':>9} {'err_rrbc':>9}"
        lines.append(f"{title} ({len(group.ids)}): correction (sensor frame) and corrected robot position, mm")
        lines.append(head)
        for k, pid in enumerate(group.ids):
            row = f"  {pid:<12} {_fmt_vec(cp.correction[k])}   {_fmt_vec(cp.robot_rrbc[k], 12, 4)}"
            if checks:
                row += f" {result.error_rigid[k]:9.4f} {result.error_rrbc[k]:9.4f}"
            if cp.extrapolated[k]:
                row += "  extrapolated"
            lines.append(row)
    s = result.summary()
    lines.append("")
    if s["rmst_rigid_mm"] is None:
        lines.append("summary: no check points, so no error can be scored")
    else:
        change = (s["rmst_rrbc_mm"] - s["rmst_rigid_mm"]) / s["rmst_rigid_mm"] * 100 if s["rmst_rigid_mm"] > 0 else 0.0
        lines.append(
            f"summary over {len(result.checks.ids)} check points: RMST rigid {s['rmst_rigid_mm']:.4f} mm, "
            f"RRBC {s['rmst_rrbc_mm']:.4f} mm ({change:+.1f} %); max rigid {s['max_rigid_mm']:.4f} mm, "
            f"RRBC {s['max_rrbc_mm']:.4f} mm"
        )
    return "\n".join(lines) + "\n"


def _cmd_correct(args) -> str:
    from .measurements import read_measurements
    from .pipeline import CorrectionOptions, correct_measurements

    mset = read_measurements(args.measurements)
    opts = CorrectionOptions(
        registration=args.registration,
        interpolation=args.interpolation,
        neighbors=args.neighbors,
        power=args.power,
        seed=args.seed,
    )
    result = correct_measurements(mset, opts)
    if args.json:
        return json.dumps(result.to_json(), allow_nan=False) + "\n"
    return _table(result)


def main(argv=None) -> int:
    try:
        args = build_parser().parse_args(argv)
        out = args.run(args)
    except (_UsageError, InputError) as exc:
        msg = " ".join(str(exc).split())
        print(f"rrbc: error: {msg}" if not msg.startswith("rrbc") else msg, file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    except Exception as exc:  # noqa: BLE001 - the contract: one line, exit 1
        if os.environ.get("RRBC_DEBUG"):
            raise
        print(f"rrbc: internal error: {type(exc).__name__}: {' '.join(str(exc).split())} "
              "(set RRBC_DEBUG=1 for details)", file=sys.stderr)
        return 1
    try:
        sys.stdout.write(out)
        sys.stdout.flush()
    except BrokenPipeError:
        return 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
