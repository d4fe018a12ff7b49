"""The `rrbc` subcommands that bring a user's cell and data in: `rrbc scene new` (a scene from a mesh and a
target list), `rrbc convert` (measurement file <-> 3D Slicer markups; stationing YAML -> measurement file) and `rrbc calibrate` (RRBC against
model-based calibration on a file with joint angles). A thin layer like `cli.py`, which adds these parsers
(`add_parsers`); same exit codes and one-line errors (docs/cli.md)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rrbc_core.cli_options import add_robot_model_options, robot_model_args
from rrbc_core.errors import InputError
from rrbc_core.io.stationing_yaml import FIDUCIAL_CHOICES, read_stationing_yaml


def _xyz(text: str):
    parts = text.split(",")
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"expected X,Y,Z in mm, got {text!r}")
    try:
        return tuple(float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected three numbers X,Y,Z in mm, got {text!r}") from None


def _gravity(text: str):
    parts = text.split(",")
    try:
        if len(parts) != 3:
            raise ValueError
        return tuple(float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected three numbers GX,GY,GZ in m/s², got {text!r}") from None


def add_parsers(sub) -> None:
    s = sub.add_parser("scene", help="make scenes", description="Make scenes for your own cell.")
    ss = s.add_subparsers(dest="scene_command", required=True, parser_class=type(s))
    n = ss.add_parser(
        "new",
        help="a complete scene from a cell mesh and a target list",
        description="Write a complete, documented scene (robot, sensor, registration points, candidate and planned "
        "fiducials, error model) from a cell mesh and a targets CSV, both in the robot's base frame, mm "
        "(docs/scene-new.md).",
    )
    n.add_argument("--mesh", required=True, help="the cell's mesh (STL, OBJ, PLY, GLB, 3MF; mm, robot frame)")
    n.add_argument("--targets", required=True, help="targets CSV: id,x,y,z[,region_mm] (mm, robot frame)")
    n.add_argument(
        "--robot", default=None, choices=("ur5", "ur10", "none"), help="the arm (default ur5; none with --urdf)"
    )
    n.add_argument(
        "--urdf",
        default=None,
        help="a robot the kinematics do not model, drawn from its URDF (a file in --out's folder or below, with its "
        "meshes; or ur5, ur10, panda, lift_arm); reach is not checked",
    )
    n.add_argument("--tip", default=None, help="with --urdf: the tool link (default: end of the longest chain)")
    n.add_argument("--sensor", type=_xyz, default=None, help="sensor position X,Y,Z in mm (default: chosen)")
    n.add_argument("--fiducials", type=int, default=6, help="fiducials the planner places at first (default 6)")
    n.add_argument("--seed", type=int, default=0, help="seed of the surface sampling, error model and planner")
    n.add_argument("--out", required=True, help="the scene file to write (.toml)")
    n.add_argument("--json", action="store_true", help="print one JSON object")
    n.set_defaults(run=_cmd_scene_new)

    c = sub.add_parser(
        "convert",
        help="measurement file <-> 3D Slicer markups; stationing YAML -> measurement file",
        description="Convert a measurement file to two 3D Slicer markups files (sensor and robot point lists, "
        "labels = ids) or back (docs/formats/slicer-markups.md); or a mobile manipulator's stationing data (YAML, "
        "the form of the public construction-robot stationing data sets) to a measurement file with one station "
        "per column height and solution space, the robot columns from the URDF's forward kinematics "
        "(docs/real_data.md).",
    )
    c.add_argument(
        "inputs",
        nargs="+",
        help="a measurement CSV (--to slicer), SENSOR.mrk.json ROBOT.mrk.json, or a stationing .yaml (--to csv)",
    )
    c.add_argument("--to", required=True, choices=("slicer", "csv"), help="what to write")
    c.add_argument("--out", required=True, help="a directory (--to slicer) or a CSV file (--to csv)")
    c.add_argument("--urdf", default=None, help="stationing YAML: the robot's URDF")
    c.add_argument(
        "--tip", default=None, help="stationing YAML: the measured link (default: the URDF's link named prism)"
    )
    c.add_argument("--base", default=None, help="stationing YAML: the base link (default: the root link)")
    c.add_argument(
        "--fiducials",
        default="stationing",
        choices=FIDUCIAL_CHOICES,
        help="stationing YAML: the stationing points are registration points and fiducials (role both); 'half' "
        "makes every other evaluation point of a station a fiducial too ('half-swapped' the other half); the rest "
        "are checks (default stationing)",
    )
    c.set_defaults(run=_cmd_convert)

    k = sub.add_parser(
        "calibrate",
        help="RRBC against model-based calibration (VEC) on a file with joint angles",
        description="Identify the arm's kinematic errors and the sensor-to-robot transform from the registration "
        "and fiducial rows (joint values: a URDF's joints in radians and metres, or q1..q6 in degrees for --robot), "
        "after checking the model against the robot columns, then predict every check and target four ways: rigid, "
        "RRBC, VEC, VEC + RRBC (docs/calibration.md).",
    )
    k.add_argument("measurements", help="measurement CSV with joint columns")
    add_robot_model_options(k, "the arm's model")
    k.add_argument(
        "--compliance",
        action="store_true",
        help="add joint compliance under gravity load (and a lift column's bending) from the URDF's link masses; "
        "terms enter where cross-validation over the fiducials says they help",
    )
    k.add_argument("--backlash", action="store_true", help="with --compliance: backlash terms too (rad)")
    k.add_argument(
        "--gravity",
        type=_gravity,
        default=None,
        help="with --compliance: gravity GX,GY,GZ in m/s² in the base frame (default 0,0,-9.80665)",
    )
    k.add_argument("--save-model", default=None, metavar="M.json", help="write the identified arm to this file")
    k.add_argument(
        "--export-urdf",
        default=None,
        metavar="CALIBRATED.urdf",
        help="with --urdf: write the identified arm as a URDF (joint origins and offsets updated, the tool as a link "
        "rrbc_tool, load terms in a comment; docs/calibration.md)",
    )
    k.add_argument(
        "--model",
        default=None,
        metavar="M.json",
        help="reuse a saved arm (from --save-model): only the sensor-to-robot transform is fitted, to the "
        "registration and fiducial rows (3 registration rows per station suffice)",
    )
    k.add_argument("--json", action="store_true", help="print one JSON object")
    k.set_defaults(run=_cmd_calibrate)


def _cmd_scene_new(args) -> str:
    from rrbc_core.authoring.scene_new import NewSceneOptions, new_scene

    robot = args.robot or ("none" if args.urdf is not None else "ur5")
    opts = NewSceneOptions(
        robot=robot, sensor=args.sensor, fiducials=args.fiducials, seed=args.seed, urdf=args.urdf, tip=args.tip
    )
    result = new_scene(args.mesh, args.targets, args.out, opts)
    s = result.summary
    if args.json:
        return json.dumps(s) + "\n"
    lines = [
        f"wrote {s['scene']}: {s['targets']} targets, {s['registration']} registration points, {s['fiducials']} "
        f"fiducials planned from {s['candidates'] + s['fiducials']} candidate locations on the mesh",
        f"sensor at ({', '.join(f'{v:.0f}' for v in s['sensor'])}) mm"
        + (f"; hidden from it: {', '.join(s['hidden_targets'])}" if s["hidden_targets"] else "; sees every target"),
        f"targets inside the fiducials' hull: {len(s['targets_inside_hull'])} of {s['targets']}"
        + (
            f"; outside: {', '.join(s['targets_outside_hull'])} (the mesh offers no candidates around them: add "
            "fiducial places at their height, or check the sensor's view)"
            if s["targets_outside_hull"]
            else ""
        ),
        f"predicted RMST over the targets' regions: rigid {s['predicted_rmst_mm']['rigid']:.3f} mm, RRBC "
        f"{s['predicted_rmst_mm']['rrbc']:.3f} mm",
        f"next: rrbc plan {s['scene']} --add 4   |   rrbc simulate {s['scene']} --out data.csv   |   rrbc view {s['scene']}",
    ]
    if args.urdf is not None:
        lines.insert(
            -1,
            f"robot: drawn from {args.urdf}; its reach is not checked (the app poses it by its tool point and hides "
            "it where it cannot reach)",
        )
    return "\n".join(lines) + "\n"


def _cmd_convert(args) -> str:
    from rrbc_core.io.measurements import read_measurements
    from rrbc_core.io.measurements_write import write_measurements
    from rrbc_core.io.slicer_markups import read_markups, write_markups

    yaml_input = len(args.inputs) == 1 and args.inputs[0].lower().endswith((".yaml", ".yml"))
    if not yaml_input and (args.urdf or args.tip or args.base or args.fiducials != "stationing"):
        raise InputError("--urdf, --tip, --base and --fiducials go with a stationing .yaml file")
    if yaml_input:
        return _convert_stationing(args)
    if args.to == "slicer":
        if len(args.inputs) != 1:
            raise InputError("convert --to slicer takes one measurement CSV")
        src = Path(args.inputs[0])
        mset = read_measurements(src)
        stem = src.name[:-4] if src.name.lower().endswith(".csv") else src.name
        paths = write_markups(mset, args.out, stem)
        return "".join(f"wrote {p}\n" for p in paths)
    if len(args.inputs) != 2:
        raise InputError("convert --to csv takes two markups files: SENSOR.mrk.json ROBOT.mrk.json")
    out = _csv_out(args.out)
    mset = read_markups(*args.inputs)
    write_measurements(out, mset, comments=[f"converted from {args.inputs[0]} and {args.inputs[1]} by rrbc convert"])
    return f"wrote {out} ({len(mset.ids)} rows)\n"


def _csv_out(path: str) -> Path:
    out = Path(path)
    if out.is_dir() or not out.parent.is_dir():
        raise InputError(f"--out {out}: must be a file in an existing directory")
    return out


def _convert_stationing(args) -> str:
    from rrbc_core.io.groups import group_names
    from rrbc_core.io.measurements_write import write_measurements
    from rrbc_core.models.urdf import load_urdf

    if args.to != "csv":
        raise InputError("a stationing .yaml file converts --to csv")
    if args.urdf is None:
        raise InputError("a stationing .yaml file needs the robot's --urdf (and --tip, the measured link)")
    out = _csv_out(args.out)
    if args.tip is None:  # the file measures a prism: its link, when the URDF names one so
        try:
            chain = load_urdf(args.urdf, tip="prism", base=args.base)
        except InputError:
            raise InputError(
                f"{Path(args.urdf).name}: no link named 'prism': give --tip, the link whose origin the instrument "
                "measured"
            ) from None
    else:
        chain = load_urdf(args.urdf, tip=args.tip, base=args.base)
    src = args.inputs[0]
    mset = read_stationing_yaml(src, chain, args.fiducials)
    write_measurements(
        out,
        mset,
        comments=[
            f"converted from {Path(src).name} by rrbc convert (--urdf {Path(args.urdf).name} --tip {chain.tip} "
            f"--fiducials {args.fiducials}); robot columns: the URDF's forward kinematics of the joint columns"
        ],
    )
    n = {r: sum(1 for x in mset.roles if x == r) for r in ("both", "fiducial", "check")}
    return (
        f"wrote {out} ({len(mset.ids)} rows, {len(group_names(mset))} stations: {n['both']} stationing points "
        f"(registration and fiducial), {n['fiducial']} further fiducials, {n['check']} checks)\n"
    )


def _cmd_calibrate(args) -> str:
    from rrbc_core.analysis.saved_model import load_model
    from rrbc_core.analysis.vec_compare import compare
    from rrbc_core.io.measurements import read_measurements

    if (args.backlash or args.gravity is not None) and not args.compliance:
        raise InputError("--backlash and --gravity go with --compliance")
    if args.model is not None and (args.compliance or args.tool is not None):
        raise InputError("--model keeps the saved arm (its tool and load terms): drop --compliance and --tool")
    from rrbc_core.io.joints import file_tool

    model = load_model(args.model) if args.model is not None else None
    mset = read_measurements(args.measurements)
    tool = args.tool if args.tool is not None or model is not None else file_tool(mset)
    result = compare(
        mset,
        tool=tool,
        compliance=args.compliance,
        backlash=args.backlash,
        gravity=args.gravity,
        model=model,
        save_model=args.save_model,
        export_urdf=args.export_urdf,
        **robot_model_args(args),
    )
    if args.json:
        return json.dumps(result) + "\n"
    return calibrate_text(result)


def calibrate_text(result: dict) -> str:
    """The text of `rrbc calibrate` for its JSON object `result` (`analysis.vec_compare.compare`)."""
    from rrbc_core.analysis.vec_compare import METHODS

    def mm(v):
        return "-" if v is None else f"{v:.4f}"

    model = result["model"]
    tool = ", ".join(f"{v:g}" for v in model["tool_mm"])
    lines = [
        f"{result['robot']} ({model['base']} → {model['tip']}, tool ({tool}) mm): the model lies "
        f"{model['check']['rms_mm']:.2f} mm RMS from the robot columns (at most {model['check']['threshold_mm']:g})",
        f"{result['poses']} poses identify {result['identifiable']['rank']} parameter combinations; residual noise "
        f"{result['residual_sigma_mm']:.4f} mm per axis",
        "method      RMST over checks   cross-validated (fiducials)",
    ]
    for m in METHODS:
        lines.append(f"{m:<11} {mm(result['rmst_mm'][m]):>16}   {mm(result['cv_rmst_mm'][m]):>12}")
    for m, sp in result.get("interpolation_space", {}).items():
        if sp["space"] == "configuration":
            cv = sp["cv_rmst_mm"]
            lines.append(
                f"{m} interpolates over the arm's configuration (joint space): cross-validated {mm(cv['configuration'])}"
                f" mm against {mm(cv['position'])} over position"
            )
    lines.append(f"recommended (chosen without the checks): {result['recommended']}")
    if result["extrapolated_share"] > 0:
        lines.append(f"recommendation: {result['recommendation_basis']}")
    k = result["kinematic_error"]
    if result["saved_model"] is not None:
        lines.append("kinematic error: the saved arm's (only the sensor-to-robot transform was fitted to this file)")
    else:
        lines += arm_verdict_lines(result)
        lines.append(
            f"identified arm errors against their uncertainty: χ² {k['chi2']:.1f} on {k['dof']} degrees of freedom "
            f"(p = {k['p_value']:.2g})"
        )
    ident = [p for p in result["parameters"] if p["identifiable"] and "kind" not in p]
    lines.append(
        "identified errors: "
        + ", ".join(f"{p['name']} {p['error']:+.4g} ± {p['std_error']:.2g}" for p in ident)
        + " (angles rad, lengths mm)"
    )
    lines += compliance_lines(result)
    lines += calibrate_bound_lines(result)
    lines += [f"warning: {w}" for w in result["warnings"]]
    return "\n".join(lines) + "\n"


def calibrate_bound_lines(result: dict) -> list[str]:
    """The targets' 95 % bound per method (mm; '-' where none) and what the bounds rest on."""
    from rrbc_core.analysis.vec_compare import METHODS

    if not result["targets"]:
        return []
    inst = result["bounds"]["instrument"]
    lines = [
        "",
        "targets: 95 % bound on the 3-D error of each method's command (mm; '-': none)",
        f"  {'id':<12}" + "".join(f" {m:>9}" for m in METHODS),
    ]
    for row in result["targets"]:
        b = row["bound95_mm"]
        lines.append(f"  {row['id']:<12}" + "".join(f" {'-' if b[m] is None else f'{b[m]:.4f}':>9}" for m in METHODS))
    lines.append(f"  noise: {inst['sigma_mm']:.4g} mm per axis, {inst['source']}")
    lines += [f"warning: {w}" for w in result["bounds"]["warnings"]]
    return lines


def arm_verdict_lines(result: dict) -> list[str]:
    """`rrbc calibrate`'s text lines on whether the file holds a kinematic error or compliance: rrbc diagnose's
    decision on the same file and model (`analysis.arm_verdict`), with the tests' p-values and sizes."""
    v = result["kinematic_error"]["verdict"]
    t = v["tests"]

    def p_of(name: str) -> str:
        if name in t:
            return f"p = {t[name]:.2g}"
        per = [p for k, p in t.items() if k.endswith(f": {name}")]  # per station
        return f"smallest p = {min(per):.2g} over {len(per)} stations" if per else "not run"

    kin = f"test {p_of('kinematic')}" + (f", beside a smooth field {p_of('kinematic_beside_field')}")
    if v["kinematic"]:
        kin += f"; {v['kinematic_rms_mm']:.3g} mm RMS over the points"
    lines = [f"kinematic error: {'yes' if v['kinematic'] else 'not named'} ({kin}; alpha {v['alpha']:g})"]
    if any(k == "compliance" or k.endswith(": compliance") for k in t) or v["compliance"]:
        comp = f"test {p_of('compliance')}"
        if v["compliance"]:
            comp += f"; {v['compliance_rms_mm']:.3g} mm RMS over the points"
            if not result["compliance"]["requested"]:
                comp += "; add --compliance to model it"
        lines.append(f"compliance: {'yes' if v['compliance'] else 'not named'} ({comp})")
    lines.append(f"  rule: {result['kinematic_error']['rule']}")
    lines += [f"  limit: {lim}" for lim in v["limits"]]
    return lines


def compliance_lines(result: dict) -> list[str]:
    """The text lines of `rrbc calibrate` about load terms and a saved model."""
    lines = []
    c = result["compliance"]
    if c["requested"]:
        table = ", ".join(f"{k} {v:.4f}" for k, v in c["cv_rmst_mm"].items())
        lines.append(f"compliance candidates: {', '.join(c['candidates']) or 'none the data can see'}")
        lines.append(f"VEC cross-validated RMS (mm): {table or '-'}")
        terms = [p for p in result["parameters"] if "kind" in p]
        lines.append(
            "load terms entered: "
            + (
                ", ".join(
                    f"{p['name']} {p['error']:+.3g}"
                    + ("" if p["std_error"] is None else f" ± {p['std_error']:.2g}")
                    + f" {p['unit']}"
                    for p in terms
                )
                or "none (cross-validation says they do not help)"
            )
        )
        if c["refused"]:
            lines.append(
                "load terms taken out: "
                + ", ".join(f"{r['name']} (identified {r['value']:+.3g} {r['unit']}: below zero)" for r in c["refused"])
                + "; an arm does not stiffen under its load, so the rest were fitted again without them"
            )
    if result["saved_model"] is not None:
        m = result["saved_model"]
        lines.append(
            f"arm from {m['path']} (identified on {m['identified_on']}, {m['poses']} poses; load terms "
            f"{', '.join(m['terms']) or 'none'}): only the sensor-to-robot transform was fitted"
        )
    if result["saved_to"] is not None:
        lines.append(f"wrote the identified arm to {result['saved_to']}")
    return lines
