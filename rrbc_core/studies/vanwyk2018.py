"""`rrbc reproduce vanwyk2018`: the whole analysis, layout by layout, as plain data.

For each assumed layout (`reproduction.layouts()`): simulate every candidate model on its direction grid,
fit each to the published tables (`model_fit`), cross-validate by leaving one method out, choose, then
derive peg success (Table III) and RRBC's predicted gain from the fitted models. Layout A also gets a
confusion study: tables generated from each model (bias 3x noise) are run through the same selection, to
show how often a single table names its true cause.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.runtime.threads import thread_limited
from rrbc_core.studies import model_fit, reference_data, reproduction
from rrbc_core.studies.reproduction import METHODS, MODELS, STATISTICS

DEFAULT_REPLICATES = 200
#: at most this many simulated experiments per model and direction (the default takes minutes; memory grows with it:
#: 200 000 asked for 12 GB within a minute)
MAX_REPLICATES = 2000
CONFUSION_TABLES = 10
CONFUSION_BIAS_TO_NOISE = 3.0
CONFUSION_SIGMA_MM = 0.15


@dataclass(frozen=True)
class PegPrediction:
    capture_mm: float  # fitted capture radius (one for all methods)
    probability: np.ndarray  # (7,) predicted success probability per insertion
    successes: np.ndarray  # (7,) expected successes of 160
    successes_90: np.ndarray  # (7, 2) 90 % range (experiments x binomial)
    ps: np.ndarray  # (7,) the paper's PS bound at the expected count
    log_likelihood: float


@dataclass(frozen=True)
class LayoutResult:
    layout: reproduction.Layout
    directions: dict  # model name -> DirectionStats
    moments: dict  # model name -> Moments
    selection: model_fit.Selection
    peg: dict  # "baseline" / chosen -> PegPrediction
    rrbc: dict  # "baseline" / chosen -> rrbc_gain dict
    intervals: dict  # chosen parameter -> (lo, hi) at deviance + 1
    confusion: dict | None  # planted model -> {chosen model: count}
    noise_sweep: tuple = ()  # RRBC gain of the best extension as its noise shrinks (rrbc_noise_sweep)


def nearest_direction(ds, phi) -> int:
    return int(np.argmin(np.abs(np.asarray(ds.phis) - phi)))


def fitted_errors(ds, fit: model_fit.Fit, kind: str = "norms") -> np.ndarray:
    """Simulated error norms ('norms') or horizontal norms ('horizontal') (R, 7, 80), mm, at the fit: the
    nearest simulated direction, scaled by the fitted rho."""
    return getattr(ds, kind)[nearest_direction(ds, fit.phi)] * np.exp(fit.log_rho)


def peg_prediction(ds, fit: model_fit.Fit, successes: np.ndarray) -> PegPrediction:
    """Fit one capture radius to the published success counts (binomial likelihood, 160 tries per method)
    from the model's horizontal errors at its fitted parameters (nearest simulated direction)."""
    h = fitted_errors(ds, fit, "horizontal")
    n = reference_data.PEG_TRIES
    grid = np.linspace(0.005, 3.0, 600)
    p = np.clip(reproduction.success_probability(h, grid), 1e-9, 1 - 1e-9)  # (C, 7)
    ll = np.sum(successes * np.log(p) + (n - successes) * np.log(1 - p), axis=1)
    c = float(grid[int(np.argmax(ll))])
    per_rep = np.mean(h < c, axis=2)  # (R, 7)
    prob = per_rep.mean(axis=0)
    rng = np.random.default_rng(0)
    draws = rng.binomial(n, np.clip(per_rep, 0, 1)[None].repeat(20, axis=0))  # (20, R, 7)
    lo, hi = np.percentile(draws.reshape(-1, len(METHODS)), [5, 95], axis=0)
    expected = prob * n
    ps = np.array([reference_data.ps_bound(int(round(m))) for m in expected])
    return PegPrediction(c, prob, expected, np.stack([lo, hi], axis=1), ps, float(ll.max()))


def _tables_from(geo, model, rho, phi, count, seed) -> list:
    ds = reproduction.simulate_model(geo, model, count, seed, phis=[phi])
    return [
        np.array([ds.values[s][0, k] * rho ** reproduction.SCALE_POWER[s] for s in STATISTICS]) for k in range(count)
    ]


def confusion_tables(layout_name: str, planted: int, count: int, seed: int) -> list:
    """`count` tables (4, 7) simulated from one planted model (index into MODELS) at sigma 0.15 mm with bias 3x
    noise (baseline: noise only), for the confusion study. One task."""
    geo = reproduction.geometry_named(layout_name)
    model = MODELS[planted]
    ph = 0.0 if model.name == "baseline" else float(np.arctan(CONFUSION_BIAS_TO_NOISE))
    rho = CONFUSION_SIGMA_MM / np.cos(ph)  # first weight (noise, or horizontal noise) = 0.15 mm
    return _tables_from(geo, model, rho, ph, count, seed + 1000 + planted)


def choose_task(task: tuple) -> str:
    """(Moments by model name, table y) -> the model assess + select chooses for it. One task."""
    moments, y = task
    return model_fit.select(model_fit.assess(moments, MODELS, y)).chosen


def layout_replicates(layout, replicates: int) -> int:
    """Experiments simulated per direction: with G > 1 registrations per experiment an experiment costs G times
    more, so half as many (still well over the 28 statistics whose covariance the fit estimates)."""
    return replicates if layout.registrations == 1 else max(replicates // 2, 5)


def simulate_task(task: tuple) -> reproduction.DirectionStats:
    """(layout name, model name, replicates, seed) -> the model's statistics on its direction grid. One task."""
    layout_name, model_name, replicates, seed = task
    return reproduction.simulate_model(
        reproduction.geometry_named(layout_name), reproduction.model_by_name(model_name), replicates, seed
    )


def assess_task(task: tuple) -> model_fit.Assessment:
    """(model name, its Moments, table y) -> fit and leave-one-method-out assessment. One task."""
    model_name, moments, y = task
    return model_fit.assess({model_name: moments}, [reproduction.model_by_name(model_name)], y)[model_name]


def analyse_layout(
    layout,
    y: np.ndarray,
    replicates: int,
    seed: int,
    directions: dict,
    moments: dict,
    assessments: dict,
    confusion: dict | None = None,
) -> LayoutResult:
    """Choose a model from the layout's assessments, then peg success, RRBC's gain, the noise sweep and the
    profile intervals of the best extension."""
    geo = reproduction.geometry_named(layout.name)
    replicates = layout_replicates(layout, replicates)
    sel = model_fit.select(assessments)
    successes = np.array([reference_data.successes_from_ps(r.ps)[0] for r in _rows_in_order()])
    names = ["baseline"] + ([sel.chosen] if sel.chosen != "baseline" else [])
    best_ext = best_extension(sel)
    if best_ext not in names:
        names.append(best_ext)
    peg = {n: peg_prediction(directions[n], assessments[n].fit, successes) for n in names}
    rrbc = {}
    for n in names:
        f = assessments[n].fit
        rrbc[n] = reproduction.rrbc_gain(
            geo, reproduction.model_by_name(n), float(np.exp(f.log_rho)), f.phi, replicates, seed + 7
        )
    sweep = rrbc_noise_sweep(geo, reproduction.model_by_name(best_ext), assessments[best_ext].fit, replicates, seed)
    model = reproduction.model_by_name(best_ext)
    intervals = {
        lab: model_fit.profile_interval(moments[best_ext], y, model, assessments[best_ext].fit, lab)
        for lab in model.labels
    }
    return LayoutResult(layout, directions, moments, sel, peg, rrbc, intervals, confusion, sweep)


NOISE_FACTORS = (1.0, 0.5, 0.25, 0.1)


def rrbc_noise_sweep(geo, model, fit: model_fit.Fit, replicates: int, seed: int) -> tuple:
    """RRBC's predicted gain with the fitted extension kept and its FIRST (noise) weight scaled by each factor:
    how the gain grows as bias comes to exceed noise (NISTIR 8300's condition). Also the rigid RMS of the
    noise part alone and of the extension alone. Rows: dicts with factor, weights, rmst and change."""
    rho = float(np.exp(fit.log_rho))
    w_noise, w_ext = rho * np.cos(fit.phi), rho * np.sin(fit.phi)
    rows = []
    for f in NOISE_FACTORS:
        wn = f * w_noise
        g = reproduction.rrbc_gain(
            geo, model, float(np.hypot(wn, w_ext)), float(np.arctan2(w_ext, wn)), replicates, seed + 11
        )
        alone = reproduction.rrbc_gain(geo, model, wn, 0.0, replicates, seed + 11)["rmst_rigid_mm"] if wn > 0 else 0.0
        rows.append(
            dict(
                g,
                factor=f,
                params=model.params(float(np.hypot(wn, w_ext)), float(np.arctan2(w_ext, wn))),
                rmst_noise_part_mm=alone,
            )
        )
    bias_alone = reproduction.rrbc_gain(geo, model, w_ext, np.pi / 2, replicates, seed + 11)["rmst_rigid_mm"]
    return tuple(dict(r, rmst_extension_part_mm=bias_alone) for r in rows)


def best_extension(sel: model_fit.Selection) -> str:
    """The chosen model, or (nothing claimed) the extension with the lowest cross-validated misfit."""
    if sel.chosen != "baseline":
        return sel.chosen
    ext = [a for k, a in sel.assessments.items() if k != "baseline"]
    return min(ext, key=lambda a: a.cv_deviance).model


def _rows_in_order():
    by = {r.method: r for r in reference_data.vanwyk2018()}
    return [by[m] for m in METHODS]


@dataclass(frozen=True)
class Reproduction:
    measured: tuple
    samples_per_method: int
    successes: np.ndarray
    layouts: tuple  # LayoutResult per layout, A first
    replicates: int
    seed: int
    seconds: float

    @property
    def main(self) -> LayoutResult:
        return self.layouts[0]

    def cause(self) -> str:
        return cause_sentence(self)

    def to_json(self) -> dict:
        main = self.main
        sel = main.selection
        ext = best_extension(sel)
        base_a, ext_a = sel.assessments["baseline"], sel.assessments[ext]

        def rows(a, peg):
            out = []
            for m, name in enumerate(METHODS):
                row: dict[str, str | float | None] = {"method": name}
                for s, stat in enumerate(STATISTICS):
                    row[stat] = float(a.fit.mean[s, m])
                    row[stat + "_sd"] = float(a.fit.sd[s, m])
                    row[stat + "_z"] = float(a.fit.z[s, m])
                row["p"] = reference_data.correlation_p(
                    float(np.clip(float(a.fit.mean[STATISTICS.index("r"), m]), -0.999, 0.999)), self.samples_per_method
                )
                ks = main.directions[a.model].values["ks_p"][
                    nearest_direction(main.directions[a.model], a.fit.phi), :, m
                ]
                row["ks_p_vs_prev_median"] = None if m == 0 else float(np.median(ks))
                row["ps"] = float(peg.ps[m])
                row["peg_successes"] = float(peg.successes[m])
                out.append(row)
            return out

        return {
            "paper": reference_data.CITATION,
            "samples_per_method": self.samples_per_method,
            "measured": [dict(r.as_dict(), peg_successes=int(m)) for r, m in zip(_rows_in_order(), self.successes)],
            "baseline": rows(base_a, main.peg["baseline"]),
            "extended": rows(ext_a, main.peg[ext]),
            "extended_model": ext,
            "claimed": sel.chosen != "baseline",
            "separated": sel.separated,
            "parameters": {
                "baseline": base_a.fit.params,
                "extended": ext_a.fit.params,
                "extended_interval": {k: list(v) for k, v in main.intervals.items()},
            },
            "misfit": {
                "baseline": base_a.fit.deviance,
                "extended": ext_a.fit.deviance,
                "baseline_cv": base_a.cv_deviance,
                "extended_cv": ext_a.cv_deviance,
                "baseline_chi2": base_a.fit.chi2,
                "extended_chi2": ext_a.fit.chi2,
                "definition": "deviance = (y-m)^T S^-1 (y-m) + ln det S over the 28 statistics (Gaussian -2 log-likelihood, full covariance S over simulated experiments); cv = leave one method out, scored given the other six",
            },
            "models": [
                {
                    "name": k,
                    "parameters": a.fit.params,
                    "misfit": a.fit.deviance,
                    "misfit_cv": a.cv_deviance,
                    "chi2": a.fit.chi2,
                    "outside_2sd": a.fit.outside(),
                }
                for k, a in sel.assessments.items()
            ],
            "peg": {
                k: {"capture_mm": v.capture_mm, "successes": v.successes.tolist(), "ps": v.ps.tolist()}
                for k, v in main.peg.items()
            },
            "rrbc": main.rrbc,
            "rrbc_noise_sweep": list(main.noise_sweep),
            "layouts": [
                {
                    "name": lr.layout.name,
                    "description": lr.layout.description,
                    "chosen": lr.selection.chosen,
                    "separated": lr.selection.separated,
                    "best_extension": best_extension(lr.selection),
                    "misfit": {k: a.fit.deviance for k, a in lr.selection.assessments.items()},
                    "misfit_cv": {k: a.cv_deviance for k, a in lr.selection.assessments.items()},
                    "parameters": {k: a.fit.params for k, a in lr.selection.assessments.items()},
                }
                for lr in self.layouts
            ],
            "confusion": main.confusion,
            "cause": self.cause(),
            "assumptions": list(main.layout.assumptions),
            "replicates": self.replicates,
            "seed": self.seed,
        }


def cause_sentence(rep: Reproduction) -> str:
    main = rep.main
    sel = main.selection
    a = sel.assessments
    base = a["baseline"]
    if sel.chosen == "baseline":
        best = best_extension(sel)
        return (
            f"No extension is supported: the best ({best}) lowers the in-sample misfit by "
            f"{base.fit.deviance - a[best].fit.deviance:.1f} (needed > {sel.threshold:.1f}) and the cross-validated "
            f"misfit from {base.cv_deviance:.1f} to {a[best].cv_deviance:.1f}; the tables are consistent with rigid "
            "truth plus isotropic noise at their sample size."
        )
    ch = a[sel.chosen]
    model = reproduction.model_by_name(sel.chosen)
    named = [f"{lr.layout.name}: {lr.selection.chosen}" for lr in rep.layouts]
    claimed = sum(lr.selection.chosen != "baseline" for lr in rep.layouts)
    smooth = {"kinematic", "flatness", "scale"}
    all_smooth = all(lr.selection.chosen in smooth for lr in rep.layouts)
    params = ", ".join(f"{k} = {v:.3g}" for k, v in ch.fit.params.items())
    text = (
        f"Rigid truth plus noise is rejected under {claimed} of {len(rep.layouts)} layouts; the data need a "
        + ("systematic, spatially smooth non-rigid error" if all_smooth else "systematic non-rigid error")
        + f" - under layout {main.layout.name} best described as {model.cause} ({params}), which lowers the misfit "
        f"from {base.fit.deviance:.1f} to {ch.fit.deviance:.1f} in sample and from {base.cv_deviance:.1f} to "
        f"{ch.cv_deviance:.1f} with each method left out"
    )
    if not sel.separated and sel.runner_up:
        text += f" (but {sel.runner_up} fits almost as well on held-out methods, {a[sel.runner_up].cv_deviance:.1f})"
    text += f"; the best-named source depends on the assumed layout ({', '.join(named)})"
    if main.confusion:
        conf = main.confusion
        diag = ", ".join(f"{k} {conf[k].get(k, 0)}/{sum(conf[k].values())}" for k in conf if k != "baseline")
        text += f", and planted single tables name their own source only sometimes ({diag})"
    text += ", so the tables establish the non-rigid error and its size but not which physical source produces it."
    if sel.chosen == "flatness":
        text += (
            f" A plate-height field of {ch.fit.params['flatness_rms_mm']:.2f} mm RMS exceeds the plate's "
            "+-0.15 mm flatness tolerance, so it stands for any smooth, mostly vertical bias (e.g. the arm's "
            "kinematic or sag errors, or the stylus seating height), not necessarily the plate itself."
        )
    return text


@thread_limited
def run(
    replicates: int = DEFAULT_REPLICATES,
    seed: int = 0,
    progress_factory=None,
    layout_names=None,
    confusion: bool = True,
    scheduler: str | None = None,
    task_log: list | None = None,
) -> Reproduction:
    """The whole analysis. progress_factory(total) -> an object with update(n) and close(), or None.

    Its independent pieces — each (layout, model) simulation, each (layout, model) assessment, each planted model's
    confusion tables and each table's choice — are tasks of `runtime.tasks` (`scheduler`: this process, "local", a dask address, or
    "auto"); each carries its own fixed seed, so the result is the same wherever they run. `task_log`: a list
    that receives each stage's task seconds when they run in this process (benchmarks/reproduce_speed.py)."""
    if isinstance(replicates, bool) or not 5 <= int(replicates) <= MAX_REPLICATES:
        raise InputError(f"--replicates must be from 5 to {MAX_REPLICATES} for vanwyk2018, got {replicates}")
    from rrbc_core.runtime.tasks import task_runner

    t0 = time.perf_counter()
    rows = reference_data.vanwyk2018()
    y = model_fit.measured_matrix(rows)
    n, _ = reference_data.samples_per_method(rows)
    successes = np.array([reference_data.successes_from_ps(r.ps)[0] for r in _rows_in_order()])
    lays = (
        reproduction.layouts() if layout_names is None else tuple(reproduction.layout_by_name(x) for x in layout_names)
    )
    # the baseline (one direction, the cheapest) last: under scheduler "auto" the first task's time is the estimate
    order = [m for m in MODELS if m.phis] + [m for m in MODELS if not m.phis]
    sims = [(lay.name, m.name, layout_replicates(lay, replicates), seed) for lay in lays for m in order]
    total = 2 * len(sims) + (len(MODELS) * (1 + CONFUSION_TABLES) if confusion else 0)
    bar = progress_factory(total) if progress_factory else None
    tick = None if bar is None else bar.update
    try:
        with task_runner(scheduler, task_log) as run_all:
            done = run_all(simulate_task, sims, tick)
            directions = {(t[0], t[1]): d for t, d in zip(sims, done)}
            moments = {k: model_fit.Moments.of(v) for k, v in directions.items()}
            keys = [(lay.name, m.name) for lay in lays for m in MODELS]
            assessed = dict(zip(keys, run_all(assess_task, [(k[1], moments[k], y) for k in keys], tick)))
            main_moments = {m.name: moments[(lays[0].name, m.name)] for m in MODELS}
            planted = [(lays[0].name, i, CONFUSION_TABLES, seed) for i in range(len(MODELS))] if confusion else []
            tables = run_all(_confusion_tables_task, planted, tick)
            chosen = run_all(choose_task, [(main_moments, y_k) for ys in tables for y_k in ys], tick)
    finally:
        if bar is not None:
            bar.close()
    results = []
    for i, lay in enumerate(lays):
        dirs = {m.name: directions[(lay.name, m.name)] for m in MODELS}
        mom = {m.name: moments[(lay.name, m.name)] for m in MODELS}
        ass = {m.name: assessed[(lay.name, m.name)] for m in MODELS}
        counts = _counts(chosen, CONFUSION_TABLES) if confusion and i == 0 else None
        results.append(analyse_layout(lay, y, replicates, seed, dirs, mom, ass, counts))
    return Reproduction(rows, n, successes, tuple(results), replicates, seed, time.perf_counter() - t0)


def _confusion_tables_task(task: tuple) -> list:
    return confusion_tables(*task)


def _counts(chosen: list, per_model: int) -> dict:
    """{planted model: {chosen model: count}}, chosen listed planted model by planted model."""
    out = {}
    for i, model in enumerate(MODELS):
        counts: dict = {}
        for c in chosen[i * per_model : (i + 1) * per_model]:
            counts[c] = counts.get(c, 0) + 1
        out[model.name] = counts
    return out
