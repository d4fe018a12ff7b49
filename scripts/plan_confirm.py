"""Confirm `rrbc plan` by Monte Carlo and measure the optimiser against random placement (issue 7).

    .venv/bin/python scripts/plan_confirm.py --out docs            # writes docs/planning.md
    .venv/bin/python scripts/plan_confirm.py --quick               # fewer trials/scenes, prints only

1. For each shipped scene: `plan(scene, add=K)`, then the predicted RMST (fast, first order) of the fiducials
   before and after adding the suggestions, each checked against Monte Carlo (`predict_rmst(..., trials=N)`)
   on the same region samples.
2. Optimiser vs random over seeded scenes (`seeded_scene`): the demo cell with its kinematic error redrawn
   (seed s), 6 of its 12 fiducials drawn at random (seed s), and a 5 x 5 x 5 candidate grid; per scene, the
   predicted RRBC RMST of the optimiser's K = 4 and the mean over the random baseline's draws.
The test suite (tests/test_planning.py) uses `seeded_scene` with other seeds.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from rrbc_core.analysis import planning
from rrbc_core.simulation.errormodels import ErrorModel
from rrbc_core.simulation.errorterms import Kinematic
from rrbc_core.io.scene import NamedPoints
from rrbc_core.io.scene_toml import load_scene
from rrbc_core.runtime.threads import apply_process_policy

SCENES = ("demo_workcell", "breadboard_vanwyk2018", "peg_in_hole_cell")
ADD = 4
TRIALS = 4000
STUDY_SEEDS = tuple(range(12))  # seeded scenes of the optimiser-vs-random study (the test uses 100+)
BASE_FIDUCIALS = 6
#: The 5 x 5 x 5 candidate grid over the demo cell (robot frame, mm): the benchmark's grid too.
GRID_AXES = (np.linspace(300.0, 650.0, 5), np.linspace(-250.0, 250.0, 5), np.linspace(0.0, 120.0, 5))


def candidate_grid() -> NamedPoints:
    g = np.stack(np.meshgrid(*GRID_AXES, indexing="ij"), axis=-1).reshape(-1, 3)
    return NamedPoints(tuple(f"G{i + 1:03d}" for i in range(len(g))), g)


def seeded_scene(seed: int, base_fiducials: int = BASE_FIDUCIALS):
    """The demo cell with the UR5's kinematic error drawn with `seed`, `base_fiducials` of its 12 fiducials
    drawn with `seed`, and the 5 x 5 x 5 candidate grid (`GRID_AXES`)."""
    scene = load_scene(ROOT / "scenes" / "demo_workcell.toml")
    rng = np.random.default_rng([seed, 11])
    keep = sorted(rng.choice(len(scene.fiducials), size=base_fiducials, replace=False))
    robot = tuple(dataclasses.replace(t, seed=int(seed)) if isinstance(t, Kinematic) else t
                  for t in scene.error_model.robot)
    model = ErrorModel(robot=robot, sensor=scene.error_model.sensor)
    return dataclasses.replace(scene, fiducials=scene.fiducials.subset([scene.fiducials.ids[i] for i in keep]),
                               candidates=candidate_grid(), error_model=model, name=f"demo seed {seed}")


def optimiser_vs_random(seeds, add: int = ADD) -> list[dict]:
    """Per seeded scene: the optimiser's and the random baseline's predicted RRBC RMST (mm), gain = 1 − opt/random."""
    rows = []
    for s in seeds:
        res = planning.plan(seeded_scene(s), add, seed=s)
        rnd = res.baselines["random"]
        rows.append({"seed": s, "optimiser": res.predicted_after.rrbc_mm, "random": rnd.rrbc_mm,
                     "random_sd": rnd.rrbc_std_mm, "corners": res.baselines["hull-corners"].rrbc_mm,
                     "before": res.predicted.rrbc_mm, "coverage_before": res.overall_coverage(),
                     "coverage_after": res.overall_coverage(after=True),
                     "gain": 1.0 - res.predicted_after.rrbc_mm / rnd.rrbc_mm})
    return rows


def confirm(trials: int, add: int = ADD) -> list[dict]:
    rows = []
    for name in SCENES:
        scene = load_scene(ROOT / "scenes" / f"{name}.toml")
        t0 = time.perf_counter()
        res = planning.plan(scene, add)
        t_plan = time.perf_counter() - t0
        before = scene.fiducials.positions
        after = np.concatenate([before, res.suggested])
        mc0 = planning.predict_rmst(scene, before, trials=trials)
        mc1 = planning.predict_rmst(scene, after, trials=trials)
        rows.append({"scene": name, "plan_s": t_plan, "suggested": res.suggested_ids, "fast0": res.predicted,
                     "fast1": res.predicted_after, "mc0": mc0, "mc1": mc1, "cov0": res.overall_coverage(),
                     "cov1": res.overall_coverage(after=True), "rejected": len(res.rejected),
                     "usable": res.n_usable, "corners": res.baselines["hull-corners"].rrbc_mm,
                     "random": res.baselines["random"].rrbc_mm})
    return rows


def _z(fast, mc, attr):
    a, b = getattr(fast, attr + "_mm"), getattr(mc, attr + "_mm")
    se = getattr(mc, attr + "_std_mm")
    return (a - b) / b * 100.0, (a - b) / se if se > 0 else float("nan")


def report(conf: list[dict], study: list[dict], trials: int, command: str) -> str:
    lines = [
        "# Fiducial planning (`rrbc plan`): confirmation by Monte Carlo",
        "",
        f"Generated by `{command}` (numbers below are that run's; do not edit by hand).",
        "Method: `rrbc_core/planning.py` (module docstring); command: `rrbc plan SCENE [--add K] [--json] [--seed S]`.",
        "",
        f"## Predicted RMST vs Monte Carlo on the placed fiducials (K = {ADD}, {trials} trials)",
        "",
        "For each shipped scene, `plan(scene, add=K)` suggests K fiducials; the fast first-order prediction of the RMS",
        "target error over the targets' regions of variability (32 region samples per target, seed 0) is compared",
        "with a Monte Carlo run of the scene's error model on the same region samples (`predict_rmst(..., trials=N)`:",
        "bias fixed, noise redrawn per trial, least-squares registration, RRBC with IDW k=4 p=2).",
        "Δ = (fast − MC)/MC; z = (fast − MC)/(MC standard error).",
        "",
        "| scene | fiducials | coverage | rigid fast | rigid MC ± se | Δ, z | RRBC fast | RRBC MC ± se | Δ, z |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in conf:
        for tag, fast, mc, cov in (("current", r["fast0"], r["mc0"], r["cov0"]),
                                   (f"+ {ADD} suggested", r["fast1"], r["mc1"], r["cov1"])):
            d1, z1 = _z(fast, mc, "rigid")
            d2, z2 = _z(fast, mc, "rrbc")
            lines.append(
                f"| {r['scene']} | {tag} | {100 * cov:.1f} % | {fast.rigid_mm:.4f} | {mc.rigid_mm:.4f} ± {mc.rigid_std_mm:.4f} "
                f"| {d1:+.2f} %, {z1:+.1f} | {fast.rrbc_mm:.4f} | {mc.rrbc_mm:.4f} ± {mc.rrbc_std_mm:.4f} | {d2:+.2f} %, {z2:+.1f} |")
    dz = [_z(r[f], r[m], a) for r in conf for f, m in (("fast0", "mc0"), ("fast1", "mc1")) for a in ("rigid", "rrbc")]
    d_max = max(abs(d) for d, _ in dz)
    z_max = max(abs(z) for _, z in dz)
    lines += ["", f"Largest |Δ| {d_max:.2f} %, largest |z| {z_max:.1f}. The test suite allows 4 Monte Carlo standard "
              "errors plus 2 % (the first-order truncation, theory notes §2.3: 1–2 %); a |z| above ~3 with a |Δ| of a "
              "few tenths of a per cent is that truncation showing once the Monte Carlo error is small."]
    lines += ["", "Predicted gain of the suggestions (RRBC RMST, mm) and its Monte Carlo confirmation:", "",
              "| scene | suggested | usable / rejected candidates | plan time | fast: before → after | MC: before → after | gain fast | gain MC | hull-corners | random (mean) |",
              "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in conf:
        g_fast = 1 - r["fast1"].rrbc_mm / r["fast0"].rrbc_mm
        g_mc = 1 - r["mc1"].rrbc_mm / r["mc0"].rrbc_mm
        se = np.hypot(r["mc1"].rrbc_std_mm / r["mc0"].rrbc_mm,
                      r["mc1"].rrbc_mm * r["mc0"].rrbc_std_mm / r["mc0"].rrbc_mm ** 2)
        lines.append(
            f"| {r['scene']} | {', '.join(r['suggested'])} | {r['usable']} / {r['rejected']} | {r['plan_s']:.2f} s "
            f"| {r['fast0'].rrbc_mm:.4f} → {r['fast1'].rrbc_mm:.4f} | {r['mc0'].rrbc_mm:.4f} → {r['mc1'].rrbc_mm:.4f} "
            f"| {100 * g_fast:.1f} % | {100 * g_mc:.1f} % ± {100 * se:.1f} % | {r['corners']:.4f} | {r['random']:.4f} |")
    g = np.array([s["gain"] for s in study])
    lines += [
        "",
        f"## Optimiser vs random placement ({len(study)} seeded scenes, K = {ADD})",
        "",
        "Seeded scenes (`scripts/plan_confirm.py: seeded_scene`): the demo cell with the UR5 kinematic error drawn",
        f"with seed s, {BASE_FIDUCIALS} of its 12 fiducials drawn with seed s, and a 5 x 5 x 5 candidate grid",
        "(x 300–650, y −250–250, z 0–120 mm; candidates under the plate are rejected as hidden). Predicted RRBC RMST",
        f"(fast) of the optimiser's K = {ADD} against the mean over {planning.RANDOM_DRAWS} random K-subsets of the usable",
        "candidates; gain = 1 − optimiser / random.",
        "",
        "| seed | coverage before → after | before | optimiser | hull-corners | random mean (sd) | gain |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for s in study:
        lines.append(f"| {s['seed']} | {100 * s['coverage_before']:.1f} → {100 * s['coverage_after']:.1f} % "
                     f"| {s['before']:.4f} | {s['optimiser']:.4f} | {s['corners']:.4f} "
                     f"| {s['random']:.4f} ({s['random_sd']:.4f}) | {100 * s['gain']:.1f} % |")
    lines += [
        "",
        f"**Margin: the optimiser's predicted RRBC RMST is {100 * g.mean():.1f} % below the random mean on average "
        f"(sd {100 * g.std(ddof=1):.1f} % over {len(g)} scenes; min {100 * g.min():.1f} %, max {100 * g.max():.1f} %).** "
        "tests/test_planning.py checks this on other seeds.",
        "",
        "Limits: the comparison uses the fast prediction, the quantity the optimiser minimises; the Monte Carlo table",
        "above is what checks that the prediction itself is right. On the breadboard every target sits on a fiducial",
        "(IDW takes that fiducial's correction), so added fiducials change nothing, and the candidate grid lies inside",
        "the site rectangle, so coverage of the corner and edge sites (whose regions straddle the hull) cannot rise.",
        "",
    ]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None, help="directory to write planning.md into")
    ap.add_argument("--quick", action="store_true", help="400 trials and 4 seeded scenes")
    ap.add_argument("--trials", type=int, default=None)
    args = ap.parse_args(argv)
    apply_process_policy()  # one BLAS thread, as the rrbc command runs (docs/threads.md)
    trials = args.trials or (400 if args.quick else TRIALS)
    seeds = STUDY_SEEDS[:4] if args.quick else STUDY_SEEDS
    conf = confirm(trials)
    study = optimiser_vs_random(seeds)
    cmd = "python scripts/plan_confirm.py" + (" --out docs" if args.out else "") + (" --quick" if args.quick else "") \
        + (f" --trials {args.trials}" if args.trials else "")
    text = report(conf, study, trials, cmd)
    if args.out:
        Path(args.out).mkdir(parents=True, exist_ok=True)
        (Path(args.out) / "planning.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
