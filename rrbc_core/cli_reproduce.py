"""`rrbc reproduce vanwyk2018` and `rrbc reproduce crpi`: hold the simulation against published measurements
(docs/cli.md). A thin layer over `studies.vanwyk2018` and `studies.crpi_study`, each writing its report with
`--out`."""

from __future__ import annotations

import json

from rrbc_core.cli_options import int_at_least, progress_bar, scheduler_option, where
from rrbc_core.errors import InputError


def add_parsers(sub) -> None:
    """Add the `reproduce` subcommand to the `rrbc` subparsers."""
    rp = sub.add_parser(
        "reproduce",
        help="hold the simulation against published measurements",
        description="Hold the simulation against published measurements. vanwyk2018: the measured tables of Van "
        "Wyk & Marvel (2018): baseline and extended error models, cross-validated misfit, peg success, layout "
        "sensitivity. crpi: NIST's point-level breadboard readings: residuals, repeatability, variogram, "
        "leave-one-site-out RRBC for every interpolation, and the error model they support. Writes a Markdown "
        "report with PNG figures to --out.",
    )
    rp.add_argument("paper", choices=["vanwyk2018", "crpi"], help="the published experiment (vanwyk2018, crpi)")
    rp.add_argument("--out", default=None, metavar="DIR", help="write report.md, figures and summary.json here")
    rp.add_argument(
        "--replicates",
        type=int_at_least(5),
        default=None,
        help="simulated experiments per model (and direction): vanwyk2018 default 200 (minutes), "
        "crpi default 1000 (seconds)",
    )
    rp.add_argument("--layouts", default=None, help="vanwyk2018: comma-separated assumed layouts (default A,B,C,D)")
    rp.add_argument(
        "--joint-replicates",
        type=int,
        default=None,
        help="crpi: simulated experiments per direction for the joint fit with the Van Wyk tables (default 100, "
        "~1 min; 0 skips it)",
    )
    rp.add_argument("--no-confusion", action="store_true", help="vanwyk2018: skip the planted-table confusion study")
    rp.add_argument("--seed", type=int, default=0, help="seed of every simulated draw (default 0)")
    scheduler_option(rp, "the independent simulations and fits")
    rp.add_argument("--json", action="store_true", help="print one JSON object")
    rp.set_defaults(run=_cmd_reproduce)


def _check_report_dir(out) -> None:
    """A bad --out is said before the study runs; a folder that does not exist yet is created when written."""
    if out is None:
        return
    from rrbc_core.io.measurements_write import output_dir

    output_dir(out)


def _cmd_reproduce_crpi(args) -> str:
    from rrbc_core.studies import crpi_study
    from rrbc_core.studies.crpi_report import write_report

    if args.layouts is not None or args.no_confusion:
        raise InputError("--layouts and --no-confusion apply to vanwyk2018 only")
    _check_report_dir(args.out)
    replicates = crpi_study.DEFAULT_REPLICATES if args.replicates is None else args.replicates
    joint = crpi_study.DEFAULT_JOINT_REPLICATES if args.joint_replicates is None else args.joint_replicates
    st = crpi_study.run(
        replicates=replicates,
        seed=args.seed,
        joint_replicates=joint,
        scheduler=where(args.scheduler),
        progress_factory=lambda total: progress_bar(total, "reproducing crpi"),
    )
    command = "rrbc reproduce crpi" + (f" --out {args.out}" if args.out else "")
    if args.replicates is not None:
        command += f" --replicates {args.replicates}"
    if args.joint_replicates is not None:
        command += f" --joint-replicates {args.joint_replicates}"
    if args.seed:
        command += f" --seed {args.seed}"
    report = write_report(st, args.out, command) if args.out else None
    j = st.to_json()
    if args.json:
        return _reproduce_json(j, report)
    lines = [
        f"NIST breadboard points (CRPI): {j['data']['sites']} sites, {j['data']['readings']} readings",
        "repeatability x, y, z: " + ", ".join(f"{v:.3f}" for v in j["repeatability_mm"]) + " mm; "
        f"rigid residual RMS {j['rigid_residual_rms_mm']:.3f} mm",
        "leave-one-site-out RMS (rigid -> RRBC): "
        + "; ".join(f"{m} {v['rmst_rigid_mm']:.3f} -> {v['rmst_rrbc_mm']:.3f} mm" for m, v in j["loso"].items()),
        f"supported model: {j['chosen']}; predicted RRBC change {100 * j['predicted_rrbc_change']['mean']:+.1f} % "
        f"({100 * j['predicted_rrbc_change']['lo95']:+.1f} to {100 * j['predicted_rrbc_change']['hi95']:+.1f} %), "
        f"measured {100 * j['measured_rrbc_change']:+.1f} %",
        "",
        "cause: " + j["cause"],
    ]
    return _reproduce_text(lines, report)


def _reproduce_json(j: dict, report) -> str:
    from rrbc_core.studies.vanwyk2018_report import json_safe

    out = json_safe(j)
    if report is not None:
        out["report"] = str(report)
    return json.dumps(out, allow_nan=False) + "\n"


def _reproduce_text(lines: list[str], report) -> str:
    if report is not None:
        lines = [*lines, "", f"report: {report}"]
    return "\n".join(lines) + "\n"


def _cmd_reproduce(args) -> str:
    from rrbc_core.studies import reproduction, vanwyk2018
    from rrbc_core.studies.vanwyk2018_report import write_report

    if args.paper == "crpi":
        return _cmd_reproduce_crpi(args)
    if args.joint_replicates is not None:
        raise InputError("--joint-replicates applies to crpi only")
    args.layouts = "A,B,C,D" if args.layouts is None else args.layouts
    args.replicates = 200 if args.replicates is None else args.replicates
    names = [x.strip() for x in args.layouts.split(",") if x.strip()]
    if not names:
        raise InputError("--layouts must name at least one layout, e.g. A,B,C")
    for name in names:
        reproduction.layout_by_name(name)
    _check_report_dir(args.out)
    rep = vanwyk2018.run(
        replicates=args.replicates,
        seed=args.seed,
        layout_names=names,
        confusion=not args.no_confusion,
        progress_factory=lambda total: progress_bar(total, "reproducing vanwyk2018"),
        scheduler=where(args.scheduler),
    )
    command = "rrbc reproduce vanwyk2018" + (f" --out {args.out}" if args.out else "")
    if args.replicates != 200:
        command += f" --replicates {args.replicates}"
    if names != ["A", "B", "C", "D"]:
        command += f" --layouts {','.join(names)}"
    if args.no_confusion:
        command += " --no-confusion"
    if args.seed:
        command += f" --seed {args.seed}"
    report = write_report(rep, args.out, command) if args.out else None
    if args.json:
        return _reproduce_json(rep.to_json(), report)
    j = rep.to_json()
    m = j["misfit"]
    lines = [
        f"Van Wyk & Marvel (2018): {j['samples_per_method']} samples per method; layouts {', '.join(names)}",
        "misfit (deviance; lower is better)   in sample   cross-validated",
        f"  baseline                          {m['baseline']:9.1f}   {m['baseline_cv']:9.1f}",
        f"  {j['extended_model']:<32}  {m['extended']:9.1f}   {m['extended_cv']:9.1f}",
        "",
        "cause: " + j["cause"],
    ]
    return _reproduce_text(lines, report)
