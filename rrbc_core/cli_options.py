"""What the `rrbc` subcommands share: the argument parser that reports usage errors in one line, argparse types with
bounds, the method-option flags derived from the option fields (`methods.method_flags`), the `--scheduler` option and
the progress bar (tqdm on stderr)."""

from __future__ import annotations

import argparse
import sys

from rrbc_core.errors import InputError


class UsageError(Exception):
    pass


class Parser(argparse.ArgumentParser):
    """argparse that reports usage errors as one line (exit 2) instead of a usage block."""

    def error(self, message):
        raise UsageError(f"{self.prog}: {message} (see '{self.prog} --help')")


def int_at_least(minimum: int):
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


positive_int = int_at_least(1)
non_negative_int = int_at_least(0)


def positive_float(text):
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
    if not v > 0 or v == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return v


def tool_type(text: str) -> float | tuple[float, float, float]:
    """`--tool`: a length Z (mm along the DH flange's z axis) or a point X,Y,Z in the tip link's frame (mm); each
    value within ±2000 mm."""
    parts = text.split(",")
    try:
        values = [float(p) if p.strip().isascii() else float("nan") for p in parts]
    except ValueError:
        values = [float("nan")]
    if len(values) not in (1, 3) or not all(abs(v) <= 2000.0 for v in values):
        raise argparse.ArgumentTypeError(
            f"expected a tool length Z or a point X,Y,Z in mm (each within ±2000), got {text[:40]!r}"
        )
    return values[0] if len(values) == 1 else (values[0], values[1], values[2])


def add_robot_model_options(parser, what: str) -> None:
    """--robot, --urdf, --tip, --base, --tool: the arm's model (`analysis.robot_model.robot_chain`)."""
    parser.add_argument(
        "--robot",
        default=None,
        choices=("ur5", "ur10"),
        help=f"{what}: a DH arm, joint columns q1..q6 in degrees (default ur5 unless --urdf)",
    )
    parser.add_argument(
        "--urdf",
        default=None,
        help=f"{what}: the robot's URDF (or a packaged one: ur5, ur10, panda); joint columns named after its "
        "actuated joints, radians and metres",
    )
    parser.add_argument(
        "--tip", default=None, help="with --urdf: the measured link (default: end of the longest chain)"
    )
    parser.add_argument("--base", default=None, help="with --urdf: the base link (default: the root link)")
    parser.add_argument(
        "--tool",
        type=tool_type,
        default=None,
        help="tool length Z along the flange axis, or point X,Y,Z in the tip link's frame, mm (default none)",
    )


def robot_model_args(args) -> dict:
    """The robot model's keyword arguments from parsed options; --robot and --urdf together are refused."""
    if args.robot is not None and args.urdf is not None:
        raise InputError("give --robot or --urdf, not both")
    return {"robot": args.robot, "urdf": args.urdf, "tip": args.tip, "base": args.base}


def progress_bar(total: int, label: str):
    """A tqdm bar on stderr (so `--json` on stdout stays clean), silent for the first second and off a terminal."""
    from tqdm import tqdm

    return tqdm(total=max(int(total), 1), desc=label, file=sys.stderr, delay=1.0, disable=None, leave=False)


def advance(bar, n: int, label: str | None = None) -> None:
    """A library progress callback `(n, label)` on a tqdm bar."""
    if label is not None:
        bar.set_description_str(label, refresh=False)
    bar.update(n)


def option_dest(flag: str) -> str:
    return "opt_" + flag.replace("-", "_")


def add_method_options(parser) -> None:
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
            dest=option_dest(flag),
            type=spec_type(spec, kind),
            default=None,
            metavar=spec.flag.upper().replace("-", "_") if spec.choices is None else None,
            choices=list(spec.choices) if spec.choices else None,
            help=" / ".join(dict.fromkeys(s.help for _, _, s in owners)),
        )


def spec_type(spec, kind):
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


def where(arg):
    from rrbc_core.runtime.tasks import command_scheduler, quiet_dask_logs

    quiet_dask_logs()  # this process is ours: failures are one line, never dask's log lines
    return command_scheduler(arg)


def scheduler_option(parser, what: str) -> None:
    parser.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help=f"where {what} run: 'in-process', 'local' (a dask cluster sized to this machine), 'local:N' or a "
        "scheduler address such as tcp://127.0.0.1:8786 (default: $RRBC_SCHEDULER, else auto: the first task runs "
        "here and, if the rest would take a minute or more, they go to a local cluster); the numbers do not change",
    )


def add_instrument_options(parser) -> None:
    """The per-point bounds' reading noise (`models.instrument`): a preset instrument and figures that override it;
    without any, the noise is estimated from the data."""
    from rrbc_core.models.instrument import INSTRUMENTS

    parser.add_argument(
        "--instrument",
        choices=list(INSTRUMENTS),
        default=None,
        help="the sensor, for the bounds' noise (docs/uncertainty.md; default: estimated from the data)",
    )
    parser.add_argument("--sensor-noise-mm", type=float, default=None, help="the sensor's per-axis noise σ, mm")
    parser.add_argument("--distance-noise-mm", type=float, default=None, help="a polar sensor's distance σ, mm")
    parser.add_argument("--angle-noise-urad", type=float, default=None, help="a polar sensor's angle σ, µrad")
    parser.add_argument("--robot-noise-mm", type=float, default=None, help="the robot's per-axis noise σ, mm")


def instrument_of(args):
    """The `Instrument` the instrument flags describe, or None (estimated from the data)."""
    from rrbc_core.models.instrument import instrument_from_flags

    return instrument_from_flags(
        args.instrument, args.sensor_noise_mm, args.distance_noise_mm, args.angle_noise_urad, args.robot_noise_mm
    )
