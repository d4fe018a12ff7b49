"""Detection power of `rrbc diagnose` (issue 6): detection rate against effect size over noise.

    python scripts/diagnosis_power.py [--quick] [--out docs] [--scheduler local|ADDRESS]

For each effect (scale, affine, drift, outliers, anisotropic_noise, smooth_field) and each geometry (a planar
6 x 6 plate and a volumetric 4 x 3 x 3 block, 36 points each, random measurement order, isotropic sensor noise
sigma = 0.02 mm per axis), seeded synthetic measurement sets are built with the effect planted at a given size
and `diagnose(mset)` (alpha = 0.01) is run on each.

Effect size (x axis):
  * scale, affine, drift, smooth_field: RMS over the points of the *non-rigid part* of the planted displacement
    (the residual of a least-squares rigid fit of the displaced onto the true robot points, 3-D length), divided
    by the per-axis noise sigma. Normalising the non-rigid part makes sizes comparable across geometries: what a
    rigid motion absorbs (for example a z-scale on a plate) does not count as signal.
  * outliers: one point displaced by x * sigma (3-D length, random direction).
  * anisotropic_noise: ratio of the noise standard deviation along the sensor's line of sight to across it.

Detection rate = fraction of data sets in which the planted effect is *named at all* (for outliers: named with
the planted id among the reported ids). The fraction in which it is *named first* is in the table too. Size 0
is clean data (shared by all panels); the false-alarm rate is the fraction of clean data sets with any effect.

Point count and measurement order (section "Point count and measurement order", bottom row of the figure):
`SCANS` reruns smooth_field on grids of 12, 36 and 100 points (planar 3x4 / 6x6 / 10x10, volumetric 3x2x2 /
4x3x3 / 5x5x4; the field length stays 250 mm) and drift in raster order on the two 36-point grids, with fewer
data sets per point (50; clean data included as size 0).

Writes OUT/diagnosis_power.md (tables) and OUT/diagnosis_power.png (one panel per effect, a line per geometry).
Every data set has its own seed (see `trial_seed`) and is one task of `rrbc_core.runtime.tasks.run_tasks`, so the
output does not depend on where the tasks ran: in this process (default), on a local dask cluster
(`--scheduler local`) or on an existing one (`--scheduler ADDRESS` or $RRBC_SCHEDULER).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from rrbc_core.runtime.tasks import command_scheduler, run_tasks
from rrbc_core.runtime.threads import apply_process_policy
from rrbc_core.studies.diagnosis_power import (
    ALPHA,
    BASE_SEED,
    EFFECTS,
    FIELD_LENGTH_MM,
    GEOMETRIES,
    SCANS,
    SIGMA,
    SIZES,
    X_LABEL,
    _hit,
    geometry,
    run_one,
    trial_seed,
)


def _where(scheduler) -> str:
    from rrbc_core.runtime.tasks import AUTO, IN_PROCESS

    w = command_scheduler(scheduler)
    if w == AUTO:
        return "in this process or on a local dask cluster (auto)"
    return (
        "in this process"
        if w in IN_PROCESS
        else ("on a local dask cluster" if w.startswith("local") else "on a dask cluster")
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--quick",
        action="store_true",
        help="8 trials per point, 40 clean (a smoke run); full: 100 per point, 500 clean per geometry",
    )
    ap.add_argument("--out", default="docs", help="output directory (default docs)")
    ap.add_argument(
        "--scheduler",
        default=None,
        help="where the data sets run: 'local' (a dask cluster sized to this machine), a dask scheduler's address, "
        "or in this process (default: $RRBC_SCHEDULER, else auto: in this process unless the first task shows the rest would take a minute or more); results do not depend on it",
    )
    args = ap.parse_args(argv)
    apply_process_policy()  # one BLAS thread, as the rrbc command runs (docs/threads.md)
    trials, clean_trials = (8, 40) if args.quick else (100, 500)
    scan_trials = 8 if args.quick else 50
    jobs, keys = [], []
    for gi, geom in enumerate(GEOMETRIES):
        for k in range(clean_trials):
            jobs.append((None, geom, 0.0, trial_seed(9, gi, 0, k)))
            keys.append((None, geom, 0.0))
        for ei, eff in enumerate(EFFECTS):
            for si, size in enumerate(SIZES[eff]):
                for k in range(trials):
                    jobs.append((eff, geom, size, trial_seed(ei, gi, si + 1, k)))
                    keys.append((eff, geom, size))
    for ci, (eff, geoms, order) in enumerate(SCANS):
        for gi, geom in enumerate(geoms):
            for si, size in enumerate((0.0,) + SIZES[eff]):
                for k in range(scan_trials):
                    jobs.append((eff if size else None, geom, size, trial_seed(10 + ci, gi, si, k), order))
                    keys.append(("scan", ci, geom, size))
    t0 = time.perf_counter()
    out = run_tasks(run_one, jobs, command_scheduler(args.scheduler))
    elapsed = time.perf_counter() - t0

    # aggregate
    clean = {g: [o for key, o in zip(keys, out) if key[0] is None and key[1] == g] for g in GEOMETRIES}
    rate, first = {}, {}
    for eff in EFFECTS:
        for geom in GEOMETRIES:
            rate[eff, geom, 0.0] = np.mean([eff in o[0] for o in clean[geom]])
            first[eff, geom, 0.0] = np.mean([bool(o[0]) and o[0][0] == eff for o in clean[geom]])
            for size in SIZES[eff]:
                sel = [o for key, o in zip(keys, out) if key == (eff, geom, size)]
                rate[eff, geom, size] = np.mean([_hit(eff, *o, first=False) for o in sel])
                first[eff, geom, size] = np.mean([_hit(eff, *o, first=True) for o in sel])
    false_alarm = {g: float(np.mean([bool(o[0]) for o in clean[g]])) for g in GEOMETRIES}
    scan = {}  # (scan, geom, size) -> (rate named, rate named first, rate only affine/scale, any effect)
    for ci, (eff, geoms, _order) in enumerate(SCANS):
        for geom in geoms:
            for size in (0.0,) + SIZES[eff]:
                sel = [o for key, o in zip(keys, out) if key == ("scan", ci, geom, size)]
                scan[ci, geom, size] = (
                    float(np.mean([eff in o[0] for o in sel])),
                    float(np.mean([bool(o[0]) and o[0][0] == eff for o in sel])),
                    float(np.mean([eff not in o[0] and bool({"affine", "scale"} & set(o[0])) for o in sel])),
                    float(np.mean([bool(o[0]) for o in sel])),
                )

    outdir = Path(args.out)
    outdir.mkdir(parents=True, exist_ok=True)
    cmd = "python scripts/diagnosis_power.py" + (" --quick" if args.quick else "") + f" --out {args.out}"
    lines = [
        "# Detection power of `rrbc diagnose`",
        "",
        f"Made by `{cmd}` (wall time {elapsed:.0f} s, tasks run {_where(args.scheduler)}); seeded and deterministic: data set "
        f"*k* of effect *e*, geometry *g*, size index *s* uses seed `{BASE_SEED} + 1000000 e + 100000 g + 1000 s + k` "
        "(clean data: e = 9, s = 0).",
        "",
        "* Geometries: planar 6 x 6 grid on a 500 x 500 mm plate; volumetric 4 x 3 x 3 grid in a 500 x 500 x 400 mm "
        "block; 36 points each, measured once each in random order (10 s apart), random sensor orientation.",
        f"* Noise: isotropic sensor noise sigma = {SIGMA} mm per axis (anisotropic_noise: sigma across the line of "
        f"sight = {SIGMA} mm, along it = ratio x {SIGMA} mm). `diagnose(mset, alpha={ALPHA})`, family-wise alpha "
        "split over the tests.",
        "* Effect size: for scale, affine, drift and smooth_field, the RMS (3-D length) of the **non-rigid part** of "
        "the planted displacement (residual of a rigid least-squares fit) divided by sigma; for outliers, one point "
        "displaced by size x sigma (3-D, random direction); for anisotropic_noise, the ratio of the noise standard "
        "deviation along / across the line of sight. Affine: a random symmetric traceless matrix (in-plane only on "
        f"the plate). Smooth field: `SmoothField(length_mm={FIELD_LENGTH_MM:g})` rescaled. Drift: random direction.",
        f"* Trials: {trials} data sets per (effect, geometry, size); {clean_trials} clean data sets per geometry, "
        "shared by all effects as size 0.",
        "* **Detection rate = fraction of data sets in which the planted effect is named at all** (outliers: with "
        "the planted id among the reported ids); in parentheses the fraction in which it is named *first*. At size 0 "
        "(clean data) it is the rate of falsely naming that effect.",
        "",
        "## False alarms on clean data",
        "",
        "| geometry | data sets | any effect reported | " + " | ".join(EFFECTS) + " |",
        "|---|---|---|" + "---|" * len(EFFECTS),
    ]
    for g in GEOMETRIES:
        lines.append(
            f"| {g} | {clean_trials} | {false_alarm[g]:.1%} | "
            + " | ".join(f"{rate[e, g, 0.0]:.1%}" for e in EFFECTS)
            + " |"
        )
    for eff in EFFECTS:
        xl = X_LABEL.get(eff, "non-rigid RMS / sigma")
        lines += [
            "",
            f"## {eff}",
            "",
            f"Size: {xl}.",
            "",
            "| geometry | "
            + " | ".join(
                ("1 (clean)" if eff == "anisotropic_noise" else "0 (clean)") if s == 0 else f"{s:g}"
                for s in ((0.0,) + SIZES[eff])
            )
            + " |",
            "|---|" + "---|" * (len(SIZES[eff]) + 1),
        ]
        for g in GEOMETRIES:
            cells = [f"{rate[eff, g, 0.0]:.1%}"] + [
                f"{rate[eff, g, s]:.0%} ({first[eff, g, s]:.0%})" for s in SIZES[eff]
            ]
            lines.append(f"| {g} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "## Point count and measurement order",
        "",
        f"{scan_trials} data sets per cell (seeds: e = 10 + scan, g = geometry index within the scan, s = size "
        "index with 0 = clean). Same generator and sizes as above; only the grid (point count) or the "
        "measurement order changes. Raster order: grid order, 10 s per point, the last grid axis fastest. Cells: "
        "named (named first) [fraction in which only a linear term was reported: affine or scale named, the "
        "planted effect not]. Size 0: fraction of clean data "
        "sets with the effect named / [any effect named].",
    ]
    lines += [
        "",
        "How `diagnose` uses this: with fewer than 40 paired points it adds a limit giving the shortest smooth-field "
        "correlation length it can see (the median distance to the 6th nearest neighbour, the reach of the Moran "
        "weights: 333 mm on the 12-point plate, 559 mm in the 12-point block, 200 mm on the 36-point plate, 260 mm "
        "in the 36-point block, against the planted 250 mm) and, when affine or scale was reported, that it may be "
        "the linear part of a smooth field. In raster order, drift directions that the fitted transform absorbs "
        "(less than 10 % of their energy left) are neither tested nor fitted, and a limit says so. On these grids "
        "raster order makes time an exact linear function of the coordinates, so a drift is indistinguishable from "
        "a linear map: it is reported as affine or scale (brackets), and the limit says drift cannot be tested.",
    ]
    for ci, (eff, geoms, order) in enumerate(SCANS):
        xl = X_LABEL.get(eff, "non-rigid RMS / sigma")
        lines += [
            "",
            f"### {eff}, {order} order, {geoms[0].split()[0]}, by point count"
            if eff == "smooth_field"
            else f"### {eff}, {order} order (compare the random-order table above)",
            "",
            f"Size: {xl}.",
            "",
            "| geometry (points) | "
            + " | ".join("0 (clean)" if v == 0 else f"{v:g}" for v in (0.0,) + SIZES[eff])
            + " |",
            "|---|" + "---|" * (len(SIZES[eff]) + 1),
        ]
        for geom in geoms:
            c0 = scan[ci, geom, 0.0]
            cells = [f"{c0[0]:.0%} / [{c0[3]:.0%}]"]
            for v in SIZES[eff]:
                c = scan[ci, geom, v]
                cells.append(f"{c[0]:.0%} ({c[1]:.0%}) [{c[2]:.0%}]")
            lines.append(f"| {geom} ({len(geometry(geom))}) | " + " | ".join(cells) + " |")
    lines += ["", "![detection-rate curves](diagnosis_power.png)", ""]
    (outdir / "diagnosis_power.md").write_text("\n".join(lines))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 3, figsize=(13, 11), constrained_layout=True)
    for ax, (ci, (eff, geoms, order)) in zip(axes[2], enumerate(SCANS)):
        xs = np.array((0.0,) + SIZES[eff])
        for geom, style in zip(geoms, ("^-", "o-", "s-")):
            ax.plot(xs, [scan[ci, geom, v][0] for v in xs], style, label=f"{geom} ({len(geometry(geom))} pts)")
        if eff == "drift":  # the random-order curves of the main panels, for comparison
            for g, style in zip(GEOMETRIES, ("o:", "s:")):
                ax.plot(
                    xs,
                    [rate[eff, g, 0.0]] + [rate[eff, g, v] for v in SIZES[eff]],
                    style,
                    alpha=0.6,
                    label=f"{g} (random order)",
                )
        ax.axhline(0.9, color="0.6", lw=0.8, ls=":")
        ax.set_title(f"{eff}: {order} order" + (", by point count" if eff == "smooth_field" else " vs random"))
        ax.set_xlabel(X_LABEL.get(eff, "non-rigid RMS / sigma"))
        ax.set_ylabel("detection rate (named)")
        ax.set_ylim(-0.03, 1.03)
        ax.grid(alpha=0.3)
        ax.legend(loc="lower right", fontsize=8)
    for ax, eff in zip(axes[:2].ravel(), EFFECTS):
        x0 = 1.0 if eff == "anisotropic_noise" else 0.0
        xs = np.array((x0,) + SIZES[eff])
        for g, style in zip(GEOMETRIES, ("o-", "s--")):
            ys = [rate[eff, g, 0.0]] + [rate[eff, g, s] for s in SIZES[eff]]
            ax.plot(xs, ys, style, label=g)
        ax.axhline(0.9, color="0.6", lw=0.8, ls=":")
        ax.set_title(eff)
        ax.set_xlabel(X_LABEL.get(eff, "non-rigid RMS / sigma"))
        ax.set_ylabel("detection rate (named)")
        ax.set_ylim(-0.03, 1.03)
        ax.grid(alpha=0.3)
        ax.legend(loc="lower right", fontsize=8)
    fig.suptitle(
        f"rrbc diagnose: detection rate, sigma = {SIGMA} mm, alpha = {ALPHA}. Top rows: 36 points, random order, "
        f"{trials} data sets per point (size 0 / ratio 1: {clean_trials} clean sets).\n"
        f"Bottom row: point count or measurement order varied, {scan_trials} data sets per point."
    )
    fig.savefig(outdir / "diagnosis_power.png", dpi=110)
    print(f"wrote {outdir / 'diagnosis_power.md'} and {outdir / 'diagnosis_power.png'} in {elapsed:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
