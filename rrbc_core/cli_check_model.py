"""`rrbc check-model DATA.csv SCENE.toml`: hold a scene's error model against a measured file (docs/check_model.md,
contract in docs/cli.md). A thin layer over `analysis.scene_check`; `--out` writes the extended scene
(`io.scene_extend`)."""

from __future__ import annotations

import json
import os

from rrbc_core.cli_options import int_at_least, positive_float


def add_parsers(sub) -> None:
    """Add the `check-model` subcommand to the `rrbc` subparsers."""
    c = sub.add_parser(
        "check-model",
        help="hold a scene's error model against a measured file: misfit, its cause, an extended scene, the gain",
        description="Simulate the scene's error model at the measured file's own points, compare the measured "
        "figures and each row with their predicted 95 % ranges, name what the model leaves unexplained (diagnose's "
        "tests), write the scene extended by it (--out) and score the extension on held-out folds "
        "(docs/check_model.md).",
    )
    c.add_argument("measurements", help="measurement CSV (docs/formats/measurement-file.md)")
    c.add_argument("scene", help="scene TOML file (scenes/README.md) whose error model is checked")
    c.add_argument("--trials", type=int_at_least(20), default=200, help="Monte Carlo trials (default 200)")
    c.add_argument("--folds", type=int_at_least(2), default=5, help="folds of the out-of-sample score (default 5)")
    c.add_argument("--alpha", type=positive_float, default=0.01, help="false-alarm rate of the naming (default 0.01)")
    c.add_argument("--seed", type=int, default=0, help="seed of the trials, folds and bootstraps (default 0)")
    c.add_argument("--out", default=None, metavar="EXTENDED.toml", help="write the extended scene here")
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.set_defaults(run=_cmd_check_model)


def _cmd_check_model(args) -> str:
    from rrbc_core.analysis.scene_check import check_scene_model
    from rrbc_core.errors import InputError
    from rrbc_core.io.measurements import read_measurements
    from rrbc_core.io.measurements_write import output_path
    from rrbc_core.io.scene_extend import check_destination, extended_scene_text, write_extended_scene
    from rrbc_core.io.scene_toml import load_scene

    if not args.alpha < 1:
        raise InputError(f"--alpha must be between 0 and 1, got {args.alpha}")
    scene = load_scene(args.scene)
    with open(args.scene, encoding="utf-8") as fh:
        text = fh.read()
    if args.out is not None:  # a bad --out is said before the work
        output_path(args.out)
        if os.path.abspath(args.out) == os.path.abspath(args.scene):
            raise InputError(f"{args.out}: --out is the scene itself; write the extended scene to another file")
        check_destination(args.scene, args.out, text)
    mset = read_measurements(args.measurements)
    res = check_scene_model(mset, scene, trials=args.trials, folds=args.folds, seed=args.seed, alpha=args.alpha)
    written = None
    if args.out is not None and res.added:
        header = f"error terms added by rrbc check-model from {os.path.basename(args.measurements)} (seed {args.seed})"
        write_extended_scene(
            args.scene, args.out, extended_scene_text(text, [(t.table, t.comment) for t in res.added], header)
        )
        written = args.out
    if args.json:
        j = res.to_json()
        j["written"] = written
        return json.dumps(j, allow_nan=False) + "\n"
    from rrbc_core.analysis.scene_check_text import check_lines

    return "\n".join(check_lines(res, args.measurements, args.scene, written)) + "\n"
