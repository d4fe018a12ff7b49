"""The `rrbc` command line (contract: docs/cli.md). A thin layer over the core.

Exit status: 0 success; 2 bad input or usage (one line on stderr, nothing on stdout); 1 unexpected internal
error (one line on stderr; set RRBC_DEBUG=1 for the traceback). Output is built completely before anything is
printed, so a failure never leaves partial output.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

from rrbc_core.errors import InputError, one_line, printable


class _UsageError(Exception):
    pass


class _Parser(argparse.ArgumentParser):
    """argparse that reports usage errors as one line (exit 2) instead of a usage block."""

    def error(self, message):
        raise _UsageError(f"{self.prog}: {message} (see '{self.prog} --help')")


def _int_at_least(minimum: int):
    """argparse type: an integer >= minimum."""

    def parse(text):
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"'{text}' is not an integer") from None
        if v < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}, got {v}")
        return v

    return parse


_positive_int = _int_at_least(1)
_non_negative_int = _int_at_least(0)


def _positive_float(text):
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
    if not v > 0 or v == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return v


def build_parser() -> argparse.ArgumentParser:
    from rrbc_core import interpolation, registration

    p = _Parser(prog="rrbc", description="Restoration of Rigid-Body Condition (RRBC): registration and corrections")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    c = sub.add_parser("correct", help="run RRBC on a measurement file", description="Run RRBC on a measurement file.")
    c.add_argument("measurements", help="measurement CSV (docs/formats/measurement-file.md)")
    c.add_argument("--registration", default="least-squares", choices=list(registration.STRATEGIES))
    c.add_argument("--interpolation", default="idw", choices=list(interpolation.METHODS))
    _method_option_flags(c)
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.set_defaults(run=_cmd_correct)

    g = sub.add_parser(
        "diagnose",
        help="find what, beyond rigid + noise, is in measured point pairs",
        description="Say what, beyond a rigid transform plus isotropic noise, is in the measured data, "
        "and whether RRBC will help.",
    )
    g.add_argument("measurements", help="measurement CSV (docs/formats/measurement-file.md)")
    g.add_argument(
        "--alpha", type=_positive_float, default=0.01, help="family-wise false-alarm rate over all tests (default 0.01)"
    )
    g.add_argument("--seed", type=int, default=0, help="seed of the bootstrap (default 0)")
    g.add_argument(
        "--robot", default="ur5", choices=("ur5", "ur10"), help="with joint columns: the arm's model (default ur5)"
    )
    g.add_argument(
        "--tool",
        type=_tool_mm,
        default=0.0,
        help="with joint columns: tool length along the flange axis, mm (default 0)",
    )
    g.add_argument("--json", action="store_true", help="print one JSON object")
    g.set_defaults(run=_cmd_diagnose)

    m = sub.add_parser(
        "simulate",
        help="simulate a scene: Monte Carlo statistics and synthetic data",
        description="Simulate a scene's robot and sensor with its error model.",
    )
    m.add_argument("scene", help="scene TOML file (scenes/README.md)")
    m.add_argument("--trials", type=_positive_int, default=200, help="Monte Carlo trials (default 200)")
    m.add_argument("--seed", type=int, default=0, help="seed of the noise, the check points and annealing (default 0)")
    m.add_argument("--out", default=None, help="write one synthetic measured data set (measurement CSV) here")
    m.add_argument("--layout", default=None, help="use a named layout of the scene (e.g. large_5pt)")
    _scheduler_option(m, "the trial chunks")
    m.add_argument(
        "--icp",
        type=_non_negative_int,
        default=0,
        metavar="N",
        help="also register by ICP of a simulated point cloud against the mesh, over N trials (~1 s each)",
    )
    m.add_argument("--json", action="store_true", help="print one JSON object")
    m.set_defaults(run=_cmd_simulate)

    pl = sub.add_parser(
        "plan",
        help="fiducial placement: coverage, predicted RMST, suggested fiducials",
        description="Whether the fiducials' hull contains each target's region of variability, the "
        "predicted RMS target error (rigid and with RRBC) and K suggested fiducials "
        "from the scene's candidate locations (docs/planning.md).",
    )
    pl.add_argument("scene", help="scene TOML file (scenes/README.md)")
    pl.add_argument(
        "--add",
        type=_non_negative_int,
        default=0,
        metavar="K",
        help="suggest K fiducials from the scene's usable candidates (default 0)",
    )
    pl.add_argument(
        "--seed", type=int, default=0, help="seed of the region samples and the random baseline (default 0)"
    )
    pl.add_argument("--json", action="store_true", help="print one JSON object")
    pl.set_defaults(run=_cmd_plan)

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
        type=_int_at_least(5),
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
    _scheduler_option(rp, "the independent simulations and fits")
    rp.add_argument("--json", action="store_true", help="print one JSON object")
    rp.set_defaults(run=_cmd_reproduce)

    v = sub.add_parser(
        "view",
        help="start the browser app",
        description="Start the browser app on a scene (default: the bundled demo scene) or a "
        "measurement file; prints the URL and runs until interrupted.",
    )
    v.add_argument(
        "scene",
        nargs="?",
        default=None,
        metavar="SCENE",
        help="scene TOML file or measurement CSV (default: the bundled default scene)",
    )
    v.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1: this machine only)")
    v.add_argument("--port", type=_non_negative_int, default=8080, help="port (default 8080; 0 = any free port)")
    v.add_argument("--mesh", default=None, help="work-cell mesh for a measurement CSV (any format trimesh reads)")
    v.add_argument(
        "--data",
        action="append",
        default=[],
        metavar="DIR",
        help="a folder whose scenes, measurement files and meshes the File tab offers (repeatable; scenes/ and the "
        "given file's folder always are)",
    )
    v.add_argument(
        "--no-token",
        action="store_true",
        help="accept connections without the per-run token (trusted setups only; pages from other sites are "
        "still refused)",
    )
    v.add_argument(
        "--per-client",
        action="store_true",
        help="one independent session per browser tab (a class: each student their own) instead of one "
        "session shared by every tab (a teacher's demo)",
    )
    v.add_argument(
        "--present",
        action="store_true",
        help="start in presentation mode: large text, collapsible panel, larger markers (for a projector)",
    )
    v.set_defaults(run=_cmd_view)

    from rrbc_core.cli_authoring import add_parsers

    add_parsers(sub)
    return p


def progress_bar(total: int, label: str):
    """A tqdm bar on stderr (so `--json` on stdout stays clean), silent for the first second and off a terminal."""
    from tqdm import tqdm

    return tqdm(total=max(int(total), 1), desc=label, file=sys.stderr, delay=1.0, disable=None, leave=False)


def _advance(bar, n: int, label: str | None = None) -> None:
    """A library progress callback `(n, label)` on a tqdm bar."""
    if label is not None:
        bar.set_description_str(label, refresh=False)
    bar.update(n)


def _dest(flag: str) -> str:
    return "opt_" + flag.replace("-", "_")


def _method_option_flags(parser) -> None:
    """One flag per method option, from the option fields' specs (`methods.method_flags`): the same names, bounds
    and help as the app's widgets; checked against the chosen methods by `MethodOptions.named`."""
    from rrbc_core.methods import method_flags

    parser.add_argument("--seed", type=int, default=0, help="seed of annealing and clustering (default 0)")
    for flag, owners in method_flags().items():
        if flag == "seed":
            continue
        spec = owners[0][2]
        kind = spec.kind if spec.kind in (int, float) else str
        parser.add_argument(
            f"--{flag}",
            dest=_dest(flag),
            type=_spec_type(spec, kind),
            default=None,
            metavar=spec.flag.upper().replace("-", "_") if spec.choices is None else None,
            choices=list(spec.choices) if spec.choices else None,
            help=" / ".join(dict.fromkeys(s.help for _, _, s in owners)),
        )


def _spec_type(spec, kind):
    """argparse type: a number of the option's kind within its bounds (else one line, exit 2)."""
    if kind is str:
        return str

    def parse(text):
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
        try:
            return spec.check(value, "")
        except InputError as exc:
            raise argparse.ArgumentTypeError(str(exc).strip()) from None

    return parse


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
            lines.append(
                f"  kernel {k}: [{_fmt_vec(pc['kernel'], 9, 2)}]  translation [{_fmt_vec(pc['translation'], 10, 4)}]"
            )
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
    for title, group, cp, checks, cov in (
        ("targets", result.targets, result.targets_corrected, False, result.targets_coverage),
        ("checks", result.checks, result.checks_corrected, True, result.checks_coverage),
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
            if checks and result.error_rrbc[k] > result.error_rigid[k]:
                row += "  RRBC worse"
            if cp.extrapolated[k]:
                row += "  extrapolated" + (f": {cov.describe(k)}" if cov is not None else "")
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
        lines += result.statistics().lines()
    return "\n".join(lines) + "\n"


def _cmd_correct(args) -> str:
    from rrbc_core.correction.pipeline import correct_measurements
    from rrbc_core.io.measurements import read_measurements
    from rrbc_core.methods import MethodOptions, method_flags

    mset = read_measurements(args.measurements)
    flags = {flag: getattr(args, _dest(flag)) for flag in method_flags() if flag != "seed"}
    opts = MethodOptions.named(args.registration, args.interpolation, seed=args.seed, **flags)
    result = correct_measurements(mset, opts)
    if args.json:
        return json.dumps(result.to_json(), allow_nan=False) + "\n"
    return _table(result)


def _tool_mm(text: str) -> float:
    try:
        v = float(text) if text.strip().isascii() else float("nan")
    except ValueError:
        v = float("nan")
    if not (0.0 <= v <= 2000.0):
        raise argparse.ArgumentTypeError(f"expected a tool length from 0 to 2000 mm, got {text[:20]!r}")
    return v


def _cmd_diagnose(args) -> str:
    from rrbc_core.analysis.diagnosis import diagnose
    from rrbc_core.analysis.diagnosis_text import diagnosis_text
    from rrbc_core.io.measurements import read_measurements

    if not args.alpha < 1:
        raise InputError(f"--alpha must be between 0 and 1, got {args.alpha}")
    mset = read_measurements(args.measurements)
    dg = diagnose(mset, alpha=args.alpha, seed=args.seed, robot=args.robot, tool_mm=args.tool)
    if args.json:
        return json.dumps(dg.to_json(), allow_nan=False) + "\n"
    return diagnosis_text(dg)


def _simulate_table(res) -> str:
    lines = [
        f"scene: {res.scene}   trials: {res.trials}   seed: {res.seed}   {res.seconds:.1f} s",
        f"points: {res.n_registration} registration, {res.n_fiducials} fiducials, {res.n_checks} check points"
        + (f"; hidden from the sensor: {', '.join(res.occluded)}" if res.occluded else ""),
        "",
        "rigid registration (TRE at check points, mm) and RRBC with IDW (k=4, p=2):",
        f"  {'strategy':<15} {'mean':>8} {'rms':>8} {'max':>8} {'r(dist)':>8}   {'rmst_rrbc':>9} {'max_rrbc':>9}",
    ]
    for st in res.strategies:
        lines.append(
            f"  {st.name:<15} {st.tre_mean_mm:8.4f} {st.tre_rms_mm:8.4f} {st.tre_max_mm:8.4f} {st.r_distance:8.3f}"
            f"   {st.rmst_rrbc_mm:9.4f} {st.max_rrbc_mm:9.4f}"
        )
    if res.interpolations:
        lines += [
            "",
            "least-squares registration + RRBC by interpolation method (mm):",
            f"  {'method':<8} {'rmst':>8} {'mean':>8} {'max':>8}",
        ]
        for it in res.interpolations:
            lines.append(f"  {it.name:<8} {it.rmst_mm:8.4f} {it.mean_mm:8.4f} {it.max_mm:8.4f}")
    return "\n".join(lines) + "\n"


def _cmd_simulate(args) -> str:
    from rrbc_core.io.measurements_write import write_measurements
    from rrbc_core.io.scene_toml import load_scene
    from rrbc_core.simulation.montecarlo import INTERPOLATION_NAMES, STRATEGY_NAMES, simulate, simulated_data

    if args.out is not None:
        from rrbc_core.io.measurements_write import output_path

        output_path(args.out)  # an empty, special or unwritable --out is refused before the run, not after
    scene = load_scene(args.scene)
    if args.layout:
        scene.with_layout(args.layout)  # an unknown layout is refused before any work
    bar = progress_bar(args.trials * (len(STRATEGY_NAMES) + len(INTERPOLATION_NAMES)) + args.icp, "simulating")
    try:
        res = simulate(
            scene,
            args.trials,
            seed=args.seed,
            layout=args.layout,
            icp=args.icp,
            progress=lambda n, label: _advance(bar, n, label),
            scheduler=_where(args.scheduler),
        )
    finally:
        bar.close()
    if args.out is not None:
        mset = simulated_data(scene, seed=args.seed, layout=args.layout)
        write_measurements(
            args.out,
            mset,
            comments=[
                f"simulated by: rrbc simulate {args.scene} --seed {args.seed}"
                + (f" --layout {args.layout}" if args.layout else ""),
                f"scene: {scene.name}; check rows carry the robot-frame truth (the command that reaches the point)",
            ],
        )
    if args.json:
        out = res.to_json()
        if args.out:
            out["out"] = str(args.out)
        return json.dumps(out, allow_nan=False) + "\n"
    text = _simulate_table(res)
    if args.out:
        text += f"\nwrote one simulated data set to {args.out}\n"
    return text


def _plan_table(res) -> str:
    from rrbc_core.interpolation.hull import OFF_PLANE_TOL_MM

    p0, p1 = res.predicted, res.predicted_after
    lines = [
        f"scene: {res.scene}   coverage of the target regions by the fiducials' hull: "
        f"{100 * res.overall_coverage():.1f} % (volume-weighted)"
    ]
    lines.append(
        f"  {'target':<12} {'hull':<8} {'coverage':>9}"
        + (f" {'after':>9} {'hull after':<10}" if res.suggested_ids else "")
    )
    word = lambda inside: "inside" if inside else "OUTSIDE"  # noqa: E731
    for k, tid in enumerate(res.target_ids):
        row = f"  {tid:<12} {word(res.inside[k]):<8} {100 * res.coverage[k]:8.1f}%"
        if res.suggested_ids:
            row += f" {100 * res.coverage_after[k]:8.1f}% {word(res.inside_after[k]):<10}"
        if not res.inside[k] and res.off_plane_mm[k] > OFF_PLANE_TOL_MM:
            row += f"  ({res.off_plane_mm[k]:.1f} mm off the fiducials' plane)"
        lines.append(row.rstrip())
    lines.append(
        "  hull: the target's own position inside the fiducials' hull (what RRBC's extrapolation flag tests); "
        "coverage: the fraction of its region of variability inside"
    )
    lines += [
        "",
        f"predicted RMST over the regions ({p0.method}), mm:",
        f"  {'fiducials':<28} {'rigid':>8} {'RRBC':>8} {'+-':>7}",
        f"  {'current':<28} {p0.rigid_mm:8.4f} {p0.rrbc_mm:8.4f} {p0.rrbc_std_mm:7.4f}",
    ]
    if res.requested:
        k = res.requested
        if res.suggested_ids:
            n = len(res.suggested_ids)
            lines.append(f"  {f'+ {n} suggested':<28} {p1.rigid_mm:8.4f} {p1.rrbc_mm:8.4f} {p1.rrbc_std_mm:7.4f}")
        for name, b in res.baselines.items():
            lines.append(
                f"  {f'+ {k} by rule {name}':<28} {b.rigid_mm:8.4f} {b.rrbc_mm:8.4f} {b.rrbc_std_mm:7.4f}"
                + ("  (mean, sd over draws)" if name == "random" else "")
            )
        lines += ["", f"suggestion: {res.note}"]
        if res.suggested_ids:
            lines.append(
                f"suggested fiducials ({res.n_usable} usable candidates, {len(res.rejected)} rejected), robot frame, mm:"
            )
        for pid, pos in zip(res.suggested_ids, res.suggested):
            lines.append(f"  {pid:<12} {_fmt_vec(pos, 9, 1)}")
    if res.rejected:
        shown = list(res.rejected.items())[:5]
        lines.append(
            "rejected candidates: "
            + "; ".join(f"{i}: {r}" for i, r in shown)
            + (f"; and {len(res.rejected) - 5} more" if len(res.rejected) > 5 else "")
        )
    return "\n".join(lines) + "\n"


def _cmd_plan(args) -> str:
    from rrbc_core.analysis.planning import plan
    from rrbc_core.io.scene_toml import load_scene

    scene = load_scene(args.scene)
    bar = progress_bar(2 * args.add + 2, "planning")
    try:
        res = plan(scene, args.add, seed=args.seed, progress=lambda n, label: _advance(bar, n, label))
    finally:
        bar.close()
    if args.json:
        return json.dumps(res.to_json(), allow_nan=False) + "\n"
    return _plan_table(res)


def _check_report_dir(out) -> None:
    from pathlib import Path

    if out is None:
        return
    if not str(out).strip():
        raise InputError("--out: an empty path; give a folder for the report")
    p = Path(out)
    if p.exists() and not p.is_dir():
        raise InputError(f"--out {p}: exists and is not a directory")
    if not p.resolve().parent.exists():
        raise InputError(f"--out {p}: parent directory {p.resolve().parent} does not exist")


def _where(arg):
    from rrbc_core.runtime.tasks import command_scheduler, quiet_dask_logs

    quiet_dask_logs()  # this process is ours: failures are one line, never dask's log lines
    return command_scheduler(arg)


def _scheduler_option(parser, what: str) -> None:
    parser.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help=f"where {what} run: 'in-process', 'local' (a dask cluster sized to this machine), 'local:N' or a "
        "scheduler address such as tcp://127.0.0.1:8786 (default: $RRBC_SCHEDULER, else auto: the first task runs "
        "here and, if the rest would take a minute or more, they go to a local cluster); the numbers do not change",
    )


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
        scheduler=_where(args.scheduler),
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
        scheduler=_where(args.scheduler),
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


def _cmd_view(args) -> str:
    import signal

    from rrbc_viz.app import serve

    if args.port > 65535:
        raise InputError(f"--port must be at most 65535, got {args.port}")
    app = serve(
        args.scene,
        host=args.host,
        port=args.port,
        mesh=args.mesh,
        per_client=args.per_client,
        present=args.present,
        token=not args.no_token,
        data_dirs=args.data,
    )
    try:
        signal.signal(signal.SIGTERM, signal.default_int_handler)  # stop cleanly on SIGTERM too
    except ValueError:  # not the main thread
        pass
    mode = "one session per browser tab" if args.per_client else "one session shared by every tab"
    print(f"rrbc view: serving {app.loaded.label} at {app.url} ({mode}; Ctrl+C to stop)", flush=True)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        pass
    finally:
        app.stop()
    return ""


def main(argv=None) -> int:
    from rrbc_core.runtime.threads import apply_process_policy

    apply_process_policy()  # one BLAS thread for the whole command (docs/threads.md)
    try:
        args = build_parser().parse_args(argv)
        out = args.run(args)
    except (_UsageError, InputError) as exc:
        msg = one_line(str(exc))
        print(f"rrbc: error: {msg}" if not msg.startswith("rrbc") else msg, file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    except Exception as exc:  # noqa: BLE001 - the contract: one line, exit 1
        if os.environ.get("RRBC_DEBUG"):
            raise
        print(
            f"rrbc: internal error: {type(exc).__name__}: {one_line(str(exc))} (set RRBC_DEBUG=1 for details)",
            file=sys.stderr,
        )
        return 1
    try:
        sys.stdout.write(printable(out))
        sys.stdout.flush()
    except BrokenPipeError:
        return 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
