"""Project benchmarks: `python benchmarks/run.py [--json] [--quick] [name ...]`.

Every benchmark is a small function in BENCHMARKS that takes `quick` (bool) and returns a list of rows:
dicts with `name`, `value`, `unit`, `baseline`, `ratio` (and optionally `note`). `ratio` is always "how many
times better than the baseline": value / baseline for throughputs (higher is better), baseline / value for
times (lower is better). Baselines are measured in the same run, on the same machine, so the ratio is
meaningful across machines even when the absolute numbers are not.

With --json, each row is printed as one JSON object per line (nothing else goes to stdout); without it, a
readable table. Names given on the command line select benchmarks by function name or row name.
To add a benchmark: write `def my_benchmark(quick: bool) -> list[dict]` and append it to BENCHMARKS.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # run from a checkout without installing

from scipy.spatial.transform import Rotation

from rrbc_core import batch, registration


# ------------------------------------------------------------------------------------------------------
# Helpers
# ------------------------------------------------------------------------------------------------------
def best_time(fn, repeats: int = 3) -> tuple[float, object]:
    """Best wall time (time.perf_counter, s) of `repeats` calls of fn(), and the last result."""
    best, out = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def throughput_row(name, unit, value, baseline, note="") -> dict:
    row = {"name": name, "value": value, "unit": unit, "baseline": baseline, "ratio": value / baseline}
    row["note"] = ("ratio = value / baseline (throughput, higher is better)" + (f"; {note}" if note else ""))
    return row


def time_row(name, value_s, baseline_s, note="") -> dict:
    row = {"name": name, "value": value_s, "unit": "s", "baseline": baseline_s, "ratio": baseline_s / value_s}
    row["note"] = ("ratio = baseline / value (time, lower is better)" + (f"; {note}" if note else ""))
    return row


# ------------------------------------------------------------------------------------------------------
# Monte Carlo throughput: least-squares registration + RRBC (IDW k=4, p=2)
# ------------------------------------------------------------------------------------------------------
def _work_cell(rng, trials: int) -> dict:
    """A realistic cell (mm): 8 registration points around a 1.2 m x 0.9 m x 0.5 m volume, 16 fiducials on a
    4 x 4 grid over a 600 x 450 mm fixture with 150 mm of relief, 20 targets inside it; a large sensor->robot
    rotation, a smooth robot bias (~0.3 mm), sensor noise 0.05 mm and robot noise 0.02 mm per axis, new
    noise in every trial. Returns the measured (T, N, 3) arrays."""
    rot = Rotation.from_rotvec([2.2, -0.9, 0.6]).as_matrix()
    trans = np.array([850.0, -420.0, 1310.0])
    cx, cy, cz = np.meshgrid([-300.0, 900.0], [-225.0, 675.0], [-150.0, 350.0])
    reg = np.c_[cx.ravel(), cy.ravel(), cz.ravel()] + rng.normal(0, 30, (8, 3))
    gx, gy = np.meshgrid(np.linspace(0, 600, 4), np.linspace(0, 450, 4))
    fid = np.c_[gx.ravel(), gy.ravel(), 150.0 * np.sin(gx.ravel() / 300.0) * np.cos(gy.ravel() / 250.0)]
    tgt = rng.uniform([30, 30, -60], [570, 420, 60], (20, 3))

    def robot(x):
        b = x @ rot.T + trans
        return b + 0.3 * np.sin(b / np.array([410.0, 530.0, 370.0]))

    def noisy(x, sigma):
        return x[None] + rng.normal(0, sigma, (trials,) + x.shape)

    return {
        "reg_s": noisy(reg, 0.05), "reg_b": noisy(robot(reg), 0.02),
        "fid_s": noisy(fid, 0.05), "fid_b": noisy(robot(fid), 0.02),
        "tgt_s": noisy(tgt, 0.05),
    }


def _baseline_ls_rrbc(c: dict, trials: int) -> tuple[np.ndarray, np.ndarray]:
    """The obvious per-trial Python loop: centre, scipy align_vectors, translation from the centroids,
    corrections with plain numpy, IDW (k=4, p=2) per target with np.argsort."""
    rigid = np.empty((trials, c["tgt_s"].shape[1], 3))
    rrbc = np.empty_like(rigid)
    for k in range(trials):
        s, b = c["reg_s"][k], c["reg_b"][k]
        cs, cb = s.mean(axis=0), b.mean(axis=0)
        rot, _ = Rotation.align_vectors(b - cb, s - cs)
        r = rot.as_matrix()
        t = cb - r @ cs
        fs = c["fid_s"][k]
        e = (c["fid_b"][k] - t) @ r - fs  # e_i = Rᵀ (b_i − t) − s_i
        for m, x in enumerate(c["tgt_s"][k]):
            d = np.linalg.norm(fs - x, axis=1)
            idx = np.argsort(d)[:4]
            if d[idx[0]] < 1e-9:
                corr = e[idx[0]]
            else:
                w = 1.0 / d[idx] ** 2
                corr = w @ e[idx] / w.sum()
            rigid[k, m] = r @ x + t
            rrbc[k, m] = r @ (x + corr) + t
    return rigid, rrbc


def _batch_ls_rrbc(c: dict, trials: int, chunk: int, hull: str) -> tuple[np.ndarray, np.ndarray]:
    rigid = np.empty((trials, c["tgt_s"].shape[1], 3))
    rrbc = np.empty_like(rigid)
    for start in range(0, trials, chunk):
        sl = slice(start, min(start + chunk, trials))
        out = batch.rrbc_batch(
            "least-squares", "idw", c["reg_s"][sl], c["reg_b"][sl], c["fid_s"][sl], c["fid_b"][sl], c["tgt_s"][sl],
            hull=hull, k=4, power=2.0,
        )
        rigid[sl], rrbc[sl] = out["robot_rigid"], out["robot_rrbc"]
    return rigid, rrbc


def mc_throughput_ls_rrbc(quick: bool) -> list[dict]:
    """Trials per second of least-squares registration + RRBC (IDW k=4, p=2) with rrbc_core.batch, against
    the per-trial loop, on the same simulated trials; both must give the same corrected targets (1e-6 mm)."""
    n_base, n_batch, chunk = (100, 4000, 2000) if quick else (300, 20_000, 2000)
    c = _work_cell(np.random.default_rng(2024), n_batch)
    _baseline_ls_rrbc(c, 5), _batch_ls_rrbc(c, chunk, chunk, "mean")  # warm-up (lazy imports, caches)
    t_base, (b_rigid, b_rrbc) = best_time(lambda: _baseline_ls_rrbc(c, n_base))
    rows = []
    for hull, name in (("mean", "mc_throughput_ls_rrbc"), ("none", "mc_throughput_ls_rrbc_no_hull")):
        t_batch, (rigid, rrbc) = best_time(lambda: _batch_ls_rrbc(c, n_batch, chunk, hull))
        diff = max(np.abs(rigid[:n_base] - b_rigid).max(), np.abs(rrbc[:n_base] - b_rrbc).max())
        assert diff < 1e-6, f"batch and baseline disagree by {diff} mm"
        note = (
            f"8 registration points, 16 fiducials, 20 targets; batch {n_batch} trials in chunks of {chunk}, "
            f"baseline {n_base} trials (per-trial loop, scipy align_vectors + argsort IDW); best of 3; "
            f"max |batch - baseline| = {diff:.1e} mm; extrapolation flags: "
            + ("hull of the trial-mean fiducials, once per chunk" if hull == "mean" else "not computed")
        )
        rows.append(throughput_row(name, "trials/s", n_batch / t_batch, n_base / t_base, note))
    return rows


# ------------------------------------------------------------------------------------------------------
# Monte Carlo throughput: simulated-annealing registration (Van Wyk & Marvel), seeded chains
# ------------------------------------------------------------------------------------------------------
def mc_throughput_annealing(quick: bool) -> list[dict]:
    """Trials per second of `annealing` registration (combinatorial start, seeded) with
    batch.annealing_batch (chains in lockstep) against registration.annealing called per trial; the results
    must be the same (1e-9 mm)."""
    iterations, n_base, n_batch = (1000, 5, 200) if quick else (5000, 10, 500)
    c = _work_cell(np.random.default_rng(7), n_batch)
    s, b = c["reg_s"], c["reg_b"]
    seeds = np.arange(n_batch)

    def loop():
        return [registration.annealing(s[k], b[k], seed=k, iterations=iterations).mapping for k in range(n_base)]

    t_base, ref = best_time(loop)
    t_batch, (a, t) = best_time(lambda: batch.annealing_batch(s, b, seeds=seeds, iterations=iterations))
    diff = max(max(np.abs(m.matrix - a[k]).max() * 1e3, np.abs(m.translation - t[k]).max()) for k, m in enumerate(ref))
    assert diff < 1e-9, f"annealing batch and loop disagree by {diff} mm"
    note = (
        f"8 registration points, {iterations} iterations per chain; batch {n_batch} trials, baseline {n_base} "
        f"trials (registration.annealing per trial); best of 3; max difference {diff:.1e} mm"
    )
    return [throughput_row("mc_throughput_annealing", "trials/s", n_batch / t_batch, n_base / t_base, note)]


# ------------------------------------------------------------------------------------------------------
def _drag_times(app, kind: str, pid: str, start, steps: int, heat: bool) -> tuple[list[float], float]:
    """Server-side seconds from a drag event to all scene updates sent (RunningApp.handle_drag under
    server.atomic), for `steps` "update" events moving `pid` by 0.5 mm each, then one "end" event."""
    app.set_layer("heatmap", heat)
    app.handle_drag(kind, pid, start, phase="start")
    times = []
    for k in range(steps):
        p = np.asarray(start, float) + [0.5 * (k + 1), 0.25 * (k % 3), 0.0]
        t0 = time.perf_counter()
        app.handle_drag(kind, pid, p, phase="update")
        times.append(time.perf_counter() - t0)
    t0 = time.perf_counter()
    app.handle_drag(kind, pid, p, phase="end")
    return times, time.perf_counter() - t0


def _full_recompute(source, heat_samples: int, repeats: int) -> float:
    """Baseline in the same run: what a drag would cost with no caches and nothing kept between events —
    a fresh session (scene loaded once) re-measuring every point, evaluating, and recomputing the heat map."""
    from rrbc_core.explorer import ExplorerSession
    from rrbc_core.scene import load_scene

    scene = load_scene(source)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        ses = ExplorerSession.from_scene(scene)
        ses.evaluate()
        ses.heat_map(heat_samples)
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def drag_latency(quick: bool) -> list[dict]:
    """Issue 4: median server-side time from a drag event to all scene updates sent, default scene and a
    stress scene (200 fiducials, 50 targets, 20 000 heat-map samples, heat map shown). Goal: median <= 10 ms.
    Baseline: a full uncached recompute of the same state (see _full_recompute). ratio = baseline / value."""
    import tempfile

    from rrbc_core.scene import default_scene_path
    from rrbc_viz.app import serve

    from stress_scene import HEAT_SAMPLES_PER_TARGET, write_stress_scene

    rows = []
    steps = 15 if quick else 60
    with tempfile.TemporaryDirectory() as tmp:
        for label, source, heat_n, target, fiducial in (
            ("default", default_scene_path(), 200, "H1", "F5"),
            ("stress", write_stress_scene(tmp), HEAT_SAMPLES_PER_TARGET, "T10", "S010"),
        ):
            app = serve(str(source))
            try:
                app.heat_samples_per_target = heat_n
                app.set_layer("heatmap", True)  # computes the heat map once (all samples) before timing
                samples = len(app.heat_map.positions) if app.heat_map is not None else 0
                baseline = _full_recompute(str(source), heat_n, 3 if quick else 5)
                for kind, pid in (("targets", target), ("fiducials", fiducial)):
                    group = app.session.layout[kind]
                    start = group.positions[group.index(pid)].copy()
                    upd, end = _drag_times(app, kind, pid, start, steps, heat=True)
                    med = float(np.median(upd))
                    note = (f"median of {steps} drag updates of {kind[:-1]} {pid}; p95 {np.percentile(upd, 95) * 1e3:.1f} ms; "
                            f"drag end (with heat-map refresh) {end * 1e3:.1f} ms; heat map shown, {samples} samples, "
                            f"refreshed at most every {app_heat_interval()} s while dragging; "
                            f"{len(app.session.layout['fiducials'].ids)} fiducials, {len(app.session.layout['targets'].ids)} targets; "
                            "goal: median <= 10 ms; baseline: a full uncached recompute of the same state")
                    rows.append(time_row(f"drag_{label}_{kind[:-1]}", med, baseline, note))
            finally:
                app.stop()
    return rows


def app_heat_interval() -> float:
    from rrbc_viz.app import HEAT_INTERVAL_S

    return HEAT_INTERVAL_S


# ------------------------------------------------------------------------------------------------------
# Issue 6: rrbc diagnose on 1000 points
# ------------------------------------------------------------------------------------------------------
def _diagnose_set(n: int, seed: int):
    """A 1000-point measurement set (mm, s): points in a 800 x 600 x 500 mm volume, a large sensor->robot
    rotation, a smooth robot bias (~0.3 mm), sensor noise 0.02 mm, random measurement order (10 s apart)."""
    from rrbc_core.measurements import MeasurementSet

    rng = np.random.default_rng(seed)
    robot = rng.uniform([100, -300, 50], [900, 300, 550], (n, 3))
    rot = Rotation.from_rotvec([2.2, -0.9, 0.6]).as_matrix()
    sensor = (robot - [500.0, 0.0, 300.0]) @ rot + [0.0, 0.0, 2000.0] + rng.normal(0, 0.02, (n, 3))
    biased = robot + 0.3 * np.sin(robot / np.array([410.0, 530.0, 370.0]))
    time_s = rng.permutation(n) * 10.0
    return MeasurementSet([f"P{i}" for i in range(n)], ["both"] * n, sensor, biased, time_s, [0] * n)


def _baseline_loo_loop(sensor: np.ndarray, robot: np.ndarray) -> tuple[float, float]:
    """Baseline: one least-squares registration of all points plus leave-one-out RRBC as a plain per-point loop
    (per left-out point: scipy align_vectors on the others, IDW k=4 p=2 from its nearest others with argsort).
    Returns the leave-one-out RMS of rigid and RRBC prediction errors."""
    def fit(s, b):
        cs, cb = s.mean(axis=0), b.mean(axis=0)
        r, _ = Rotation.align_vectors(b - cb, s - cs)
        r = r.as_matrix()
        return r, cb - r @ cs

    fit(sensor, robot)  # the registration of all points
    n = len(sensor)
    e_rigid, e_rrbc = np.empty((n, 3)), np.empty((n, 3))
    for i in range(n):
        keep = np.arange(n) != i
        s, b = sensor[keep], robot[keep]
        r, t = fit(s, b)
        e = b - (s @ r.T + t)
        d = np.linalg.norm(s - sensor[i], axis=1)
        idx = np.argsort(d)[:4]
        w = 1.0 / d[idx] ** 2
        e_rigid[i] = robot[i] - (r @ sensor[i] + t)
        e_rrbc[i] = e_rigid[i] - w @ e[idx] / w.sum()
    rms = lambda x: float(np.sqrt(np.mean(np.sum(x**2, axis=1))))  # noqa: E731
    return rms(e_rigid), rms(e_rrbc)


def diagnose_1000_points(quick: bool) -> list[dict]:
    """Issue 6: wall time of rrbc_core.diagnosis.diagnose on a 1000-point measurement set (median of runs),
    against a baseline measured in the same run: one least-squares registration + leave-one-out RRBC as a plain
    per-point loop (_baseline_loo_loop) on the same points. Goal: diagnose < 2 s."""
    from rrbc_core.diagnosis import diagnose

    repeats = 3 if quick else 5
    mset = _diagnose_set(1000, 606)
    sensor, robot = np.asarray(mset.sensor), np.asarray(mset.robot)
    diagnose(_diagnose_set(50, 1))  # warm-up (lazy imports)
    d_times, b_times = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        dg = diagnose(mset)
        d_times.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        loo = _baseline_loo_loop(sensor, robot)
        b_times.append(time.perf_counter() - t0)
    value, base = float(np.median(d_times)), float(np.median(b_times))
    note = (f"1000 points, smooth 0.3 mm bias, noise 0.02 mm; median of {repeats} runs; diagnose found "
            f"{dg.names or 'nothing'}, LOO RMS rigid/RRBC {dg.loo_rms_rigid_mm:.4f}/{dg.loo_rms_rrbc_mm:.4f} mm "
            f"(baseline loop {loo[0]:.4f}/{loo[1]:.4f} mm); baseline: one least-squares registration + "
            f"leave-one-out RRBC (IDW k=4, p=2) as a per-point Python loop; goal: diagnose < 2 s "
            f"({'met' if value < 2.0 else 'NOT met'})")
    return [time_row("diagnose_1000_points", value, base, note)]


# ------------------------------------------------------------------------------------------------------
# Issue 7: rrbc plan, choose 4 of 125 candidates
# ------------------------------------------------------------------------------------------------------
def plan_choose_4_of_125(quick: bool) -> list[dict]:
    """Issue 7: wall time of rrbc_core.planning.plan(scene, add=4) on the demo cell with a 5 x 5 x 5 candidate
    grid (x 300-650, y -250-250, z 0-120 mm; scripts/plan_confirm.py: candidate_grid) and 6 of its fiducials
    (F1, F3, F5, F6, F9, F10: some target regions stick out of their hull). The whole call: candidate checks
    (ray casts, reach), the prediction model, greedy + exchange, baselines. Baseline, measured in the same run:
    the same number of fiducial-set evaluations as the optimiser made, done one set at a time with the public
    fast prediction (planning.predict_rmst), timed on a sample of sets and scaled up. Goal: < 5 s."""
    import dataclasses

    from rrbc_core import planning
    from rrbc_core.scene import load_scene

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "scripts"))
    from plan_confirm import candidate_grid

    demo = load_scene(Path(__file__).resolve().parent.parent / "scenes" / "demo_workcell.toml")
    scene = dataclasses.replace(demo, fiducials=demo.fiducials.subset(["F1", "F3", "F5", "F6", "F9", "F10"]),
                                candidates=candidate_grid())
    planning.plan(scene, 1)  # warm-up (lazy imports, open3d)
    value, res = best_time(lambda: planning.plan(scene, 4), repeats=1 if quick else 3)
    rng = np.random.default_rng(7)
    cand = scene.candidates.positions
    base = scene.fiducials.positions
    cand = cand[np.min(np.linalg.norm(cand[:, None] - base[None], axis=2), axis=1) > 1e-6]  # not on a fiducial
    sample = 10 if quick else 40
    t0 = time.perf_counter()
    for _ in range(sample):
        pick = cand[rng.choice(len(cand), 4, replace=False)]
        planning.predict_rmst(scene, np.concatenate([base, pick]))
    per_set = (time.perf_counter() - t0) / sample
    baseline = per_set * res.evaluations
    note = (f"{len(scene.candidates)} candidates ({res.n_usable} usable, {len(res.rejected)} rejected), {res.evaluations} sets "
            f"evaluated; chose {', '.join(res.suggested_ids)}; predicted RRBC RMST {res.predicted.rrbc_mm:.4f} -> "
            f"{res.predicted_after.rrbc_mm:.4f} mm, coverage {100 * res.overall_coverage():.0f} -> "
            f"{100 * res.overall_coverage(True):.0f} %; baseline: {res.evaluations} x predict_rmst one set at a time "
            f"({per_set * 1e3:.1f} ms per set, mean of {sample}); goal: < 5 s ({'met' if value < 5.0 else 'NOT met'})")
    return [time_row("plan_choose_4_of_125", value, baseline, note)]


BENCHMARKS = [mc_throughput_ls_rrbc, mc_throughput_annealing, drag_latency, diagnose_1000_points, plan_choose_4_of_125]


def _format_table(rows: list[dict]) -> str:
    head = f"{'benchmark':<34} {'value':>14} {'baseline':>14} {'unit':<10} {'ratio':>8}"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r['name']:<34} {r['value']:>14.6g} {r['baseline']:>14.6g} {r['unit']:<10} {r['ratio']:>7.1f}x")
    notes = [f"  {r['name']}: {r['note']}" for r in rows if r.get("note")]
    return "\n".join(lines + ([""] + notes if notes else []))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="one JSON object per line")
    parser.add_argument("--quick", action="store_true", help="fewer trials (a few seconds in all)")
    parser.add_argument("names", nargs="*", help="run only these benchmarks (function or row names)")
    args = parser.parse_args(argv)
    functions = {fn.__name__ for fn in BENCHMARKS}
    by_row = [n for n in args.names if n not in functions]  # row names: run every benchmark, keep those rows
    selected = [fn for fn in BENCHMARKS if not args.names or by_row or fn.__name__ in args.names]
    rows = []
    for fn in selected:
        for row in fn(args.quick):
            if args.names and fn.__name__ not in args.names and row["name"] not in args.names:
                continue
            rows.append(row)
            if args.json:
                print(json.dumps(row), flush=True)
    if not args.json:
        print(_format_table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
