"""The `rrbc` command line (contract: docs/cli.md). A thin layer over the core.

Exit status: 0 success; 2 bad input or usage (one line on stderr, nothing on stdout); 1 unexpected internal
error (one line on stderr; set RRBC_DEBUG=1 for the traceback). Output is built completely before anything is
printed, so a failure never leaves partial output.
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import json
import os
import sys
import time
from collections.abc import Iterator

from rrbc_core.cli_options import (
    Parser,
    UsageError,
    add_instrument_options,
    add_method_options,
    add_robot_model_options,
    advance,
    instrument_of,
    non_negative_int,
    option_dest,
    positive_float,
    positive_int,
    progress_bar,
    robot_model_args,
    scheduler_option,
    tool_type,
    where,
)
from rrbc_core.cli_text import correct_text, plan_text, report_text, simulate_text, stations_text
from rrbc_core.errors import InputError, one_line, printable, printable_bytes
from rrbc_core.io.json_stream import PrintableAscii

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    from rrbc_core import interpolation, registration

    p = Parser(prog="rrbc", description="Restoration of Rigid-Body Condition (RRBC): registration and corrections")
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)

    c = sub.add_parser("correct", help="run RRBC on a measurement file", description="Run RRBC on a measurement file.")
    c.add_argument("measurements", help="measurement CSV (docs/formats/measurement-file.md)")
    c.add_argument("--registration", default="least-squares", choices=list(registration.STRATEGIES))
    c.add_argument("--interpolation", default="idw", choices=list(interpolation.METHODS))
    add_method_options(c)
    add_instrument_options(c)
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.add_argument(
        "--out",
        default=None,
        metavar="CORRECTED.csv",
        help="also write the corrected targets and checks (id, role, robot_x/y/z the robot is sent to, bound95_mm, "
        "extrapolated; docs/cli.md) to this CSV",
    )
    c.set_defaults(run=_cmd_correct)

    rp = sub.add_parser(
        "report",
        help="an acceptance report: every method, every point, a verdict against a tolerance (HTML or JSON)",
        description="The integrator's acceptance report of a measured cell: what was measured, the registration, "
        "the methods side by side with the recommended one, before/after figures, every point with its error and "
        "95 % bound, what rrbc diagnose names, and a verdict against --tolerance (docs/cli.md).",
    )
    rp.add_argument("measurements", help="measurement CSV (docs/formats/measurement-file.md)")
    rp.add_argument("--tolerance", type=positive_float, default=None, metavar="MM", help="the tolerance, mm")
    rp.add_argument("--out", default=None, metavar="REPORT.html", help="write the self-contained HTML report here")
    rp.add_argument("--interpolation", default="idw", choices=list(interpolation.METHODS))
    add_instrument_options(rp)
    add_robot_model_options(rp, "adds rrbc calibrate's VEC methods (a file with joint columns)")
    rp.add_argument("--json", action="store_true", help="print one JSON object")
    rp.set_defaults(run=_cmd_report)

    g = sub.add_parser(
        "diagnose",
        help="find what, beyond rigid + noise, is in measured point pairs",
        description="Say what, beyond a rigid transform plus isotropic noise, is in the measured data, "
        "and whether RRBC will help.",
    )
    g.add_argument("measurements", help="measurement CSV (docs/formats/measurement-file.md)")
    g.add_argument(
        "--alpha", type=positive_float, default=0.01, help="family-wise false-alarm rate over all tests (default 0.01)"
    )
    g.add_argument("--seed", type=int, default=0, help="seed of the bootstrap (default 0)")
    add_robot_model_options(g, "with joint columns")
    from rrbc_core.models.instrument import INSTRUMENTS  # numpy only: the parser stays light

    g.add_argument(
        "--instrument",
        choices=list(INSTRUMENTS),
        default=None,
        help="the sensor: a scale beyond what it plausibly has is said to be implausible (docs/limits.md)",
    )
    g.add_argument("--json", action="store_true", help="print one JSON object")
    g.set_defaults(run=_cmd_diagnose)

    m = sub.add_parser(
        "simulate",
        help="simulate a scene: Monte Carlo statistics and synthetic data",
        description="Simulate a scene's robot and sensor with its error model.",
    )
    m.add_argument("scene", help="scene TOML file (scenes/README.md)")
    m.add_argument("--trials", type=positive_int, default=200, help="Monte Carlo trials (default 200)")
    m.add_argument("--seed", type=int, default=0, help="seed of the noise, the check points and annealing (default 0)")
    m.add_argument("--out", default=None, help="write one synthetic measured data set (measurement CSV) here")
    m.add_argument("--layout", default=None, help="use a named layout of the scene (e.g. large_5pt)")
    scheduler_option(m, "the trial chunks")
    m.add_argument(
        "--icp",
        type=non_negative_int,
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
        type=non_negative_int,
        default=0,
        metavar="K",
        help="suggest K fiducials from the scene's usable candidates (default 0)",
    )
    pl.add_argument(
        "--seed", type=int, default=0, help="seed of the region samples and the random baseline (default 0)"
    )
    pl.add_argument(
        "--tolerance",
        type=float,
        default=None,
        metavar="MM",
        help="find the fewest candidates bringing every target's 95 %% bound under MM (docs/uncertainty.md)",
    )
    pl.add_argument("--json", action="store_true", help="print one JSON object")
    pl.set_defaults(run=_cmd_plan)

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
    v.add_argument("--port", type=non_negative_int, default=8080, help="port (default 8080; 0 = any free port)")
    v.add_argument("--mesh", default=None, help="work-cell mesh for a measurement CSV (any format trimesh reads)")
    v.add_argument(
        "--urdf",
        default=None,
        help="for a measurement CSV with joint columns: the robot's URDF (or ur5, ur10, panda, lift_arm), drawn with "
        "its meshes at the selected point's joint values",
    )
    v.add_argument(
        "--simple-arm",
        action="store_true",
        help="draw a scene's arm as links and joints instead of its meshes (lighter on a machine without a GPU)",
    )
    v.add_argument(
        "--plain-light",
        action="store_true",
        help="light the cell without the environment map (a machine without a GPU draws each frame with less work)",
    )
    v.add_argument("--tip", default=None, help="with --urdf: the measured link (default: end of the longest chain)")
    v.add_argument("--base", default=None, help="with --urdf: the base link (default: the root link)")
    v.add_argument(
        "--tool",
        type=tool_type,
        default=None,
        help="with --urdf: the measured point X,Y,Z (or Z along the flange axis) in the tip link's frame, mm "
        "(default: the file's tool columns, else the tip link's origin)",
    )
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
        "--allow-host",
        action="append",
        default=[],
        metavar="NAME",
        help="a host name the browser may use to reach the app besides localhost, IP addresses and --host "
        "(repeatable; other names are refused against DNS rebinding)",
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

    from rrbc_core import cli_authoring, cli_check_model, cli_reproduce

    cli_reproduce.add_parsers(sub)
    cli_authoring.add_parsers(sub)
    cli_check_model.add_parsers(sub)
    return p


def _cmd_correct(args) -> str | Iterator[str | bytes]:
    from rrbc_core.correction.stations import StationsResult, correct_stations
    from rrbc_core.io.measurements import read_measurements
    from rrbc_core.methods import MethodOptions, method_flags

    if args.out is not None:
        from rrbc_core.io.measurements_write import output_path

        output_path(args.out)  # a bad --out is said before the run
    mset = read_measurements(args.measurements)
    flags = {flag: getattr(args, option_dest(flag)) for flag in method_flags() if flag != "seed"}
    opts = MethodOptions.named(args.registration, args.interpolation, seed=args.seed, **flags)
    result = correct_stations(mset, opts, instrument_of(args))
    written = ""
    # one object for the file and stdout; its rows are made while they are written (a million rows stay small)
    j = result.to_json(lazy=True) if args.out is not None or args.json else {}
    if args.out is not None:
        from rrbc_core.io.corrected_write import write_corrected

        n = write_corrected(args.out, j)
        written = f"wrote {n} corrected targets and checks to {args.out}\n"
    if args.json:
        from rrbc_core.io.json_stream import json_bytes

        return itertools.chain(json_bytes(j), [b"\n"])
    return (stations_text(result) if isinstance(result, StationsResult) else correct_text(result)) + written


def _cmd_report(args) -> str:
    from rrbc_core.analysis.acceptance import acceptance
    from rrbc_core.io.joints import file_tool
    from rrbc_core.io.measurements import read_measurements
    from rrbc_core.methods import MethodOptions

    if args.out is not None:
        from rrbc_core.io.measurements_write import output_path

        output_path(args.out)  # a bad --out is said before the run
    model = robot_model_args(args)
    mset = read_measurements(args.measurements)
    tool = args.tool if args.tool is not None else file_tool(mset)
    acc = acceptance(
        mset,
        tolerance_mm=args.tolerance,
        options=MethodOptions.named("least-squares", args.interpolation),
        instrument=instrument_of(args),
        tool=tool,
        **model,
    )
    written = ""
    if args.out is not None:
        from rrbc_core.analysis.acceptance_html import report_html
        from rrbc_core.io.measurements_write import atomic_write_text

        atomic_write_text(args.out, report_html(acc))
        written = f"wrote the report to {args.out}\n"
    if args.json:
        return json.dumps(acc, allow_nan=False) + "\n"
    return report_text(acc) + written


def _cmd_diagnose(args) -> str:
    from rrbc_core.analysis.diagnosis_stations import StationsDiagnosis, diagnose_stations
    from rrbc_core.analysis.diagnosis_text import diagnosis_text
    from rrbc_core.io.measurements import read_measurements

    if not args.alpha < 1:
        raise InputError(f"--alpha must be between 0 and 1, got {args.alpha}")
    from rrbc_core.io.joints import file_tool

    mset = read_measurements(args.measurements)
    tool = args.tool if args.tool is not None else file_tool(mset)
    dg = diagnose_stations(
        mset, alpha=args.alpha, seed=args.seed, tool_mm=tool, instrument=args.instrument, **robot_model_args(args)
    )
    if args.json:
        return json.dumps(dg.to_json(), allow_nan=False) + "\n"
    if isinstance(dg, StationsDiagnosis):
        return "\n".join(dg.lines()) + "\n"
    return diagnosis_text(dg)


def _cmd_simulate(args) -> str:
    from rrbc_core.io.measurements_write import write_measurements
    from rrbc_core.io.scene_toml import load_scene
    from rrbc_core.simulation.datasets import simulated_data
    from rrbc_core.simulation.montecarlo import INTERPOLATION_NAMES, STRATEGY_NAMES, simulate

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
            progress=lambda n, label: advance(bar, n, label),
            scheduler=where(args.scheduler),
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
    text = simulate_text(res)
    if args.out:
        text += f"\nwrote one simulated data set to {args.out}\n"
    return text


def _cmd_plan(args) -> str:
    from rrbc_core.analysis.planning import plan
    from rrbc_core.io.scene_toml import load_scene

    scene = load_scene(args.scene)
    if args.tolerance is not None:
        from rrbc_core.session.tolerance_plan import MAX_FIDUCIALS, plan_to_tolerance, tolerance_text

        if args.add:
            raise InputError("--tolerance finds how many fiducials are needed: drop --add")
        from rrbc_core.correction.bounds import MIN_FIDUCIALS

        bar = progress_bar(MAX_FIDUCIALS - MIN_FIDUCIALS + 1, "planning")
        try:
            tres = plan_to_tolerance(scene, args.tolerance, progress=lambda n, label: advance(bar, n, label))
        finally:
            bar.close()
        return json.dumps(tres.to_json(), allow_nan=False) + "\n" if args.json else tolerance_text(tres)
    bar = progress_bar(2 * args.add + 2, "planning")
    try:
        res = plan(scene, args.add, seed=args.seed, progress=lambda n, label: advance(bar, n, label))
    finally:
        bar.close()
    if args.json:
        return json.dumps(res.to_json(), allow_nan=False) + "\n"
    return plan_text(res)


def _cmd_view(args) -> str:
    import signal

    from rrbc_viz.serve import serve

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
        allow_hosts=args.allow_host,
        data_dirs=args.data,
        urdf=args.urdf,
        tip=args.tip,
        base=args.base,
        tool=args.tool,
        simple_arm=args.simple_arm,
        plain_light=args.plain_light,
    )
    try:
        signal.signal(signal.SIGTERM, signal.default_int_handler)  # stop cleanly on SIGTERM too
    except ValueError:  # not the main thread
        pass
    mode = "one session per browser tab" if args.per_client else "one session shared by every tab"
    try:  # from the line that gives the URL on: Ctrl+C at once (a reader may act on the line) stops cleanly
        print(f"rrbc view: serving {app.loaded.label} at {app.url} ({mode}; Ctrl+C to stop)", flush=True)
        while True:  # short sleeps: a SIGINT the kernel hands to another thread is then acted on within one
            time.sleep(0.25)  # (one long sleep left Ctrl+C unanswered for as long under load: tests/viz/test_viz.py)
    except KeyboardInterrupt:
        pass
    finally:
        app.stop()
    return ""


def main(argv=None) -> int:
    from rrbc_core.runtime.threads import apply_process_policy

    try:
        args = build_parser().parse_args(argv)  # --help and a bad flag end here, before any library is loaded
        apply_process_policy()  # one BLAS thread for the whole command (docs/threads.md)
        out = args.run(args)
    except (UsageError, InputError) as exc:
        msg = one_line(str(exc))
        print(f"rrbc: error: {msg}" if not msg.startswith("rrbc") else msg, file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    except Exception as exc:  # the contract: one line, exit 1 (re-raised under RRBC_DEBUG)
        if os.environ.get("RRBC_DEBUG"):
            raise
        print(
            f"rrbc: internal error: {type(exc).__name__}: {one_line(str(exc))} (set RRBC_DEBUG=1 for details)",
            file=sys.stderr,
        )
        return 1
    start = _file_offset(sys.stdout)
    try:
        if isinstance(out, str):
            sys.stdout.write(printable(out))
        else:  # written as it is made (`io.json_stream`): text or, for a long JSON, UTF-8 bytes
            buffer = getattr(sys.stdout, "buffer", None)
            for piece in out:
                if not isinstance(piece, bytes):
                    sys.stdout.write(printable(piece))
                elif buffer is not None:
                    sys.stdout.flush()
                    buffer.write(piece if isinstance(piece, PrintableAscii) else printable_bytes(piece))
                else:
                    sys.stdout.write(printable(piece.decode("utf-8", errors="replace")))
        sys.stdout.flush()
    except BrokenPipeError:
        return 0
    except KeyboardInterrupt:  # Ctrl+C while written: no part of the output left either
        _cut_back(sys.stdout, start)
        return 130
    except Exception as exc:  # made while written: the same one line as above, and no part of the output left
        _cut_back(sys.stdout, start)
        if os.environ.get("RRBC_DEBUG"):
            raise
        print(f"rrbc: internal error: {type(exc).__name__}: {one_line(str(exc))}", file=sys.stderr)
        return 1
    return 0


def _file_offset(stream) -> int | None:
    """Where a command's output starts when stdout is a regular file (`> out.json`), else None (a pipe, a terminal,
    a stream without a file descriptor)."""
    import stat

    try:
        fd = stream.fileno()
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return None
        stream.flush()
        return os.lseek(fd, 0, os.SEEK_CUR)
    except (AttributeError, OSError, ValueError):
        return None


def _cut_back(stream, start: int | None) -> None:
    """Output that failed while written: a regular file is cut back to where the command's output began, so no part
    of it is left; a pipe keeps what was sent (a strict prefix of a JSON object, which no parser accepts) and the
    exit code says it failed."""
    if start is None:
        return
    with contextlib.suppress(AttributeError, OSError, ValueError):
        buffer = getattr(stream, "buffer", None)
        with contextlib.suppress(Exception):  # drop what is still buffered: it is part of the failed output
            stream.flush()
            if buffer is not None:
                buffer.flush()
        fd = stream.fileno()
        os.ftruncate(fd, start)
        os.lseek(fd, start, os.SEEK_SET)
        with contextlib.suppress(Exception):
            stream.seek(start)


if __name__ == "__main__":
    sys.exit(main())
