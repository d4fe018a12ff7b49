"""The Van Wyk tables and the CRPI points fitted jointly (issue 17, item 2; docs/reference/crpi.md).

Two of `rrbc reproduce vanwyk2018`'s models have a counterpart on the points, with the same physical parameters:

- ``seating``   — per-reading noise σ (mm per axis) + per-hole seating offset h (mm per axis, the same every time
  the hole is used);
- ``kinematic`` — per-reading noise σ + a UR5 DH error field of size κ (reference units).

For parameters (ρ, φ) of a model (its `reproduction.Model.params`), the joint misfit is the sum of the two data
sets' deviances (−2 log-likelihood; the data sets are independent):

- the tables: `model_fit.Moments.deviance_grid` on layout A (the 28 statistics, full covariance over simulated
  experiments, as in `rrbc reproduce vanwyk2018`);
- the points: −2 × [the restricted likelihood of the ten site-mean residuals under noise σ²/n plus the model's
  site component (`crpi_models`), plus the likelihood of the within-site scatter of the 100 readings under σ].

Each model is fitted three ways — tables alone, points alone, jointly — on the (ρ, φ) grid of `model_fit`, and
RRBC's leave-one-site-out gain on the plate (`reproduction.rrbc_gain`, the −35 % headline) is predicted at the
tables-alone and at the joint parameters.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core.studies import crpi, crpi_models, model_fit, reference_data
from rrbc_core.studies import reproduction as rp

JOINT_MODELS = {"seating": "seating", "kinematic": "kinematic"}  # reproduction model -> crpi component
_PHI_POINTS = 61


@dataclass(frozen=True)
class JointFit:
    model: str
    tables_only: dict  # params, deviance_tables, deviance_points (at the tables' fit), rrbc_change
    points_only: dict  # params, deviance_points, deviance_tables
    joint: dict  # params, deviance_tables, deviance_points, deviance, rrbc_change


def _points_deviance_grid(sites: crpi.Sites, component: str, model: rp.Model, log_rho, phis) -> np.ndarray:
    """−2 log-likelihood of the points (residual REML + within-site scatter) on the (ρ, φ) grid."""
    lay = crpi_models.layout_of(sites)
    _, r = crpi.rigid_fit(sites.truth, sites.means)
    y = r.reshape(-1)
    k = crpi_models._kernel(lay, component)
    ss = sum(float(np.sum((g - g.mean(axis=0)) ** 2)) for g in sites.readings)
    dof = 3 * int(np.sum(sites.counts - 1))
    n_rep = np.repeat(sites.counts, 3).astype(float)
    out = np.empty((len(log_rho), len(phis)))
    for i, lr in enumerate(log_rho):
        for j, phi in enumerate(phis):
            p = model.params(float(np.exp(lr)), float(phi))
            sigma = max(float(p["sigma_mm"]), 1e-3)  # the readings scatter: a smaller noise is impossible anyway
            size = float(p["hole_offset_mm"] if component == "seating" else p["dh_scale"])
            c = np.diag(sigma**2 / n_rep) + size**2 * k
            within = -0.5 * (dof * np.log(2 * np.pi * sigma**2) + ss / sigma**2)
            out[i, j] = -2 * (crpi_models.reml(y, lay.x, c) + within)
    return out


def run(replicates: int = 100, seed: int = 0, sites: crpi.Sites | None = None, rrbc_replicates: int = 200) -> list:
    """Joint fits of the JOINT_MODELS (layout A). `replicates` simulated experiments per direction for the tables'
    moments (`rrbc reproduce vanwyk2018` uses 200)."""
    return [fit_task(t) for t in tasks(replicates, seed, sites, rrbc_replicates)]


def tasks(replicates: int = 100, seed: int = 0, sites: crpi.Sites | None = None, rrbc_replicates: int = 200) -> list:
    """One independent task per joint model (`fit_task`), in JOINT_MODELS order."""
    sites = crpi.load() if sites is None else sites
    y = model_fit.measured_matrix(reference_data.vanwyk2018())
    return [(name, comp, y, sites, replicates, seed, rrbc_replicates) for name, comp in JOINT_MODELS.items()]


def fit_task(task: tuple) -> JointFit:
    """(model, component, tables, sites, replicates, seed, rrbc replicates) -> its JointFit (layout A)."""
    name, comp, y, sites, replicates, seed, rrbc_replicates = task
    geo = rp.geometry_named("A")
    return _fit_model(name, comp, geo, y, sites, replicates, seed, rrbc_replicates)


def _fit_model(name, component, geo, y, sites, replicates, seed, rrbc_replicates) -> JointFit:
    model = rp.model_by_name(name)
    idx = model_fit.stat_index(np.ones(len(rp.METHODS), bool))
    moments = model_fit.Moments.of(rp.simulate_model(geo, model, replicates, seed))
    log_rho = model_fit._LOG_RHO[::4]
    phis = np.linspace(moments.phis[0], moments.phis[-1], _PHI_POINTS)
    d_tab = moments.deviance_grid(y, idx, log_rho, phis)
    d_pts = _points_deviance_grid(sites, component, model, log_rho, phis)

    def at(grid):
        a, b = np.unravel_index(int(np.argmin(grid)), grid.shape)
        rho, phi = float(np.exp(log_rho[a])), float(phis[b])
        return model.params(rho, phi), float(d_tab[a, b]), float(d_pts[a, b]), (rho, phi)

    def gain(rho_phi):
        return rp.rrbc_gain(geo, model, rho_phi[0], rho_phi[1], rrbc_replicates, seed + 11)["change"]

    t_par, t_tab, t_pts, t_rp = at(d_tab)
    p_par, p_tab, p_pts, _ = at(d_pts)
    j_par, j_tab, j_pts, j_rp = at(d_tab + d_pts)
    return JointFit(
        name,
        {"params": t_par, "deviance_tables": t_tab, "deviance_points": t_pts, "rrbc_change": gain(t_rp)},
        {"params": p_par, "deviance_points": p_pts, "deviance_tables": p_tab},
        {"params": j_par, "deviance_tables": j_tab, "deviance_points": j_pts, "deviance": j_tab + j_pts,
         "rrbc_change": gain(j_rp)},
    )  # fmt: skip


def to_json(fits: list, replicates: int) -> dict:
    best = min(fits, key=lambda f: f.joint["deviance"])
    return {
        "models": {
            f.model: {"tables_only": f.tables_only, "points_only": f.points_only, "joint": f.joint} for f in fits
        },
        "chosen": best.model,
        "rrbc_change_joint": best.joint["rrbc_change"],
        "layout": "A",
        "replicates": replicates,
        "definition": "joint misfit = tables' deviance (28 statistics, layout A) + points' deviance (-2 x [REML of "
        "the site-mean residuals + likelihood of the within-site scatter]) at the same physical parameters",
    }
