"""Monte Carlo throughput rows: the vectorised kernels of `rrbc_core.simulation.batch` against the per-trial loop a competent
numpy user would write, on the same simulated trials; both must give the same corrected targets.

Not interactive (a sweep, not a click), so measured on an idle machine only.
"""

from __future__ import annotations

import numpy as np
from harness import best_time, row
from scipy.spatial.transform import Rotation

from rrbc_core import registration
from rrbc_core.simulation import batch


def work_cell(rng, trials: int) -> dict:
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
        "reg_s": noisy(reg, 0.05),
        "reg_b": noisy(robot(reg), 0.02),
        "fid_s": noisy(fid, 0.05),
        "fid_b": noisy(robot(fid), 0.02),
        "tgt_s": noisy(tgt, 0.05),
    }


def per_trial_loop(c: dict, trials: int, rotation: str = "svd") -> tuple[np.ndarray, np.ndarray]:
    """The fair baseline: one Python iteration per trial, everything inside a trial vectorised, as a competent
    numpy user writes it. Kabsch with the reflection fix by `np.linalg.svd` of the 3x3 cross-covariance
    (rotation="svd") or scipy's `Rotation.align_vectors` on centred points ("align"); corrections
    e = Rᵀ(b − t) − s for all fiducials at once; IDW (k=4, p=2) for ALL targets of the trial at once
    (squared distances (M, N), `np.argpartition` for the 4 nearest, weights 1/d²)."""
    m = c["tgt_s"].shape[1]
    rigid = np.empty((trials, m, 3))
    rrbc = np.empty_like(rigid)
    for k in range(trials):
        s, b = c["reg_s"][k], c["reg_b"][k]
        cs, cb = s.mean(axis=0), b.mean(axis=0)
        if rotation == "svd":
            u, _, vt = np.linalg.svd((s - cs).T @ (b - cb))
            d = 1.0 if np.linalg.det(vt.T @ u.T) >= 0 else -1.0
            r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
        else:
            r = Rotation.align_vectors(b - cb, s - cs)[0].as_matrix()
        t = cb - r @ cs
        fs, q = c["fid_s"][k], c["tgt_s"][k]
        e = (c["fid_b"][k] - t) @ r - fs
        d2 = np.sum((q[:, None, :] - fs[None, :, :]) ** 2, axis=2)
        idx = np.argpartition(d2, 3, axis=1)[:, :4]
        w = 1.0 / np.take_along_axis(d2, idx, axis=1)
        corr = np.einsum("mk,mkc->mc", w, e[idx]) / w.sum(axis=1, keepdims=True)
        rigid[k] = q @ r.T + t
        rrbc[k] = (q + corr) @ r.T + t
    return rigid, rrbc


def batched(c: dict, trials: int, chunk: int, hull: str = "mean") -> tuple[np.ndarray, np.ndarray]:
    rigid = np.empty((trials, c["tgt_s"].shape[1], 3))
    rrbc = np.empty_like(rigid)
    for start in range(0, trials, chunk):
        sl = slice(start, min(start + chunk, trials))
        out = batch.rrbc_batch(
            "least-squares",
            "idw",
            c["reg_s"][sl],
            c["reg_b"][sl],
            c["fid_s"][sl],
            c["fid_b"][sl],
            c["tgt_s"][sl],
            hull=hull,
            k=4,
            power=2.0,
        )
        rigid[sl], rrbc[sl] = out["robot_rigid"], out["robot_rrbc"]
    return rigid, rrbc


def mc_throughput_ls_rrbc(quick: bool) -> list[dict]:
    """Trials per second of least-squares registration + RRBC (IDW k=4, p=2) with `batch.rrbc_batch` (20 000
    trials in chunks of 2 000, extrapolation flags included) against `per_trial_loop` (the faster of its two
    rotation methods, both timed), on the same trials; results must agree to 1e-6 mm. Goal: ratio >= 30."""
    n_base, n_batch, chunk = (300, 4000, 2000) if quick else (2000, 20_000, 2000)
    c = work_cell(np.random.default_rng(2024), n_batch)
    per_trial_loop(c, 5), per_trial_loop(c, 5, "align"), batched(c, chunk, chunk)  # warm-up
    loops = {name: best_time(lambda name=name: per_trial_loop(c, n_base, name)) for name in ("svd", "align")}
    fastest = min(loops, key=lambda k: loops[k][0])
    t_base, (b_rigid, b_rrbc) = loops[fastest]
    t_batch, (rigid, rrbc) = best_time(lambda: batched(c, n_batch, chunk))
    diff = max(np.abs(rigid[:n_base] - b_rigid).max(), np.abs(rrbc[:n_base] - b_rrbc).max())
    assert diff < 1e-6, f"batch and baseline disagree by {diff} mm"
    value, base = n_batch / t_batch, n_base / t_base
    note = (
        f"8 registration points, 16 fiducials, 20 targets; batch {n_batch} trials in chunks of {chunk} "
        f"(extrapolation flags on the trial-mean hull included); baseline: per-trial loop over {n_base} trials "
        f"({', '.join(f'{k} {n_base / v[0]:.0f} trials/s' for k, v in loops.items())}; the faster, {fastest}, "
        f"is the baseline); best of 3; max |batch - baseline| = {diff:.1e} mm"
    )
    return [
        row(
            "mc_throughput_ls_rrbc",
            value,
            "trials/s",
            baseline=base,
            higher_is_better=True,
            goal="ratio >= 30",
            met=bool(value / base >= 30),
            note=note,
        )
    ]


def mc_throughput_annealing(quick: bool) -> list[dict]:
    """Trials per second of `annealing` registration (combinatorial start, seeded) with batch.annealing_batch
    (chains in lockstep) against registration.annealing called per trial — the only way to run the published
    algorithm per trial; the results must be the same (1e-9 mm)."""
    iterations, n_base, n_batch = (1000, 5, 200) if quick else (5000, 10, 500)
    c = work_cell(np.random.default_rng(7), n_batch)
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
    return [
        row(
            "mc_throughput_annealing",
            n_batch / t_batch,
            "trials/s",
            baseline=n_base / t_base,
            higher_is_better=True,
            note=note,
        )
    ]
