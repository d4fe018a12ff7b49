"""The report of `rrbc reproduce crpi --out DIR`: report.md, summary.json and three figures, written atomically
(a temporary folder beside DIR, then moved in)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from rrbc_core.studies import crpi
from rrbc_core.studies.crpi_study import Study
from rrbc_core.studies.vanwyk2018_report import _plt, json_safe, save_figure, write_folder

FIGURES = ("crpi_residuals.png", "crpi_variogram.png", "crpi_loso.png")


def _fig_residuals(st: Study, path: Path) -> None:
    """Residual vectors at the sites (plate frame N, in-plane arrows; colour: vertical part)."""
    plt = _plt()
    r_n = st.rigid_residuals_mm @ _rotation(st)  # robot -> frame N: r_N = Rᵀ r
    t = st.sites.truth
    fig, ax = plt.subplots(figsize=(6.4, 5.2))
    q = ax.quiver(t[:, 0], t[:, 1], r_n[:, 0], r_n[:, 1], r_n[:, 2], cmap="coolwarm", scale=1 / 250, scale_units="xy")
    ax.quiverkey(q, 0.85, 1.03, 0.5, "0.5 mm (x 250)", labelpos="E", coordinates="axes")
    for k, (x, y) in enumerate(t[:, :2]):
        ax.annotate(f"S{k + 1}", (x, y), textcoords="offset points", xytext=(6, -12), fontsize=8)
    fig.colorbar(q, ax=ax, label="vertical residual (mm)")
    ax.set_xlabel("plate x (mm)")
    ax.set_ylabel("plate y (mm)")
    ax.set_title("Rigid-fit residual per site (in-plane arrows, 250x)", pad=22)
    ax.set_aspect("equal")
    ax.margins(0.15)
    save_figure(fig, path, 90)


def _rotation(st: Study) -> np.ndarray:
    mapping, _ = crpi.rigid_fit(st.sites.truth, st.sites.means)
    return mapping.rotation


def _fig_variogram(st: Study, path: Path) -> None:
    plt = _plt()
    v = st.variogram
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    ax.errorbar(
        v.distance_mm, v.gamma_mm2, yerr=1.96 * np.array(v.se_mm2), fmt="ko", capsize=3, label="measured (95 %)"
    )
    for name, colour in ((st.chosen, "tab:green"), ("kinematic", "tab:red"), ("smooth_400mm", "tab:blue")):
        g = np.array(st.predictions[name].gamma_mm2)
        ax.plot(v.distance_mm, g[:, 0], "-", color=colour, label=f"{name} (mean, 95 % band)")
        ax.fill_between(v.distance_mm, g[:, 1], g[:, 2], color=colour, alpha=0.15)
    ax.set_xlabel("site separation (mm)")
    ax.set_ylabel("semivariance of the residuals (mm²)")
    ax.set_yscale("log")
    ax.set_title("Variogram: measured against models fitted to the same points")
    ax.legend(fontsize=8)
    save_figure(fig, path, 90)


def _fig_loso(st: Study, j: dict, path: Path) -> None:
    plt = _plt()
    names = [m["name"] for m in j["models"]]
    pr = np.array([[m["predictions"]["rrbc_change"][k] for k in ("mean", "lo95", "hi95")] for m in j["models"]])
    fig, ax = plt.subplots(figsize=(7.2, 4.6))
    y = np.arange(len(names))
    ax.errorbar(100 * pr[:, 0], y, xerr=100 * np.abs(pr[:, 1:].T - pr[:, 0]), fmt="o", color="0.3", capsize=3)
    ax.axvline(100 * st.measured_change, color="tab:green", label=f"measured {100 * st.measured_change:+.1f} %")
    ax.set_yticks(y, names, fontsize=8)
    ax.set_xlabel("RRBC / rigid − 1 at the held-out site (%), IDW k = 4, p = 2")
    ax.set_title("Leave-one-site-out: each model's prediction (95 % of simulated experiments)")
    ax.legend(fontsize=8)
    save_figure(fig, path, 90)


def markdown(st: Study, command: str, j: dict | None = None) -> str:
    j = st.to_json() if j is None else j
    lines = [
        "# NIST breadboard points (CRPI): what they hold",
        "",
        f"Made by `{command}`. Data: {crpi.CITATION}, copied unchanged to "
        "`rrbc_core/data/nist_crpi_registration_data1.csv`; the method: docs/reference/crpi.md.",
        "",
        "## Verdict",
        "",
        j["cause"],
        "",
        "## Facts measured without a model",
        "",
        f"- {j['data']['sites']} sites, {j['data']['readings']} readings; repeatability (pooled within-site standard "
        f"deviation) x, y, z = {', '.join(f'{v:.3f}' for v in j['repeatability_mm'])} mm.",
        f"- Rigid fit of the site means: residual RMS {j['rigid_residual_rms_mm']:.3f} mm.",
        "",
        "| site | truth x, y, z (mm) | residual x, y, z (mm, robot frame) | abs (mm) |",
        "|---|---|---|---|",
    ]
    for k, s in enumerate(j["sites"]):
        r = np.array(s["residual_mm"])
        lines.append(
            f"| S{k + 1} | {', '.join(f'{v:g}' for v in s['truth_mm'])} | {', '.join(f'{v:+.3f}' for v in r)} | "
            f"{np.linalg.norm(r):.3f} |"
        )
    lines += [
        "",
        f"![residuals]({FIGURES[0]})",
        "",
        "Variogram (γ = ½ mean |r_i − r_j|² over site pairs; jackknife standard error over sites):",
        "",
        "| separation (mm) | pairs | γ (mm²) | se (mm²) |",
        "|---|---|---|---|",
    ]
    for b in j["variogram"]["bins"]:
        hi = "∞" if b["hi_mm"] is None else f"{b['hi_mm']:.0f}"
        lines.append(
            f"| {b['lo_mm']:.0f}–{hi} (mean {b['distance_mm']:.0f}) | {b['pairs']} | {b['gamma_mm2']:.3f} | {b['se_mm2']:.3f} |"
        )
    lines += [
        "",
        f"![variogram]({FIGURES[1]})",
        "",
        "Leave-one-site-out (least squares on the other nine site means; RMS over the ten sites of the distance to "
        "the held-out site's mean reading):",
        "",
        "| interpolation | RMS rigid (mm) | RMS RRBC (mm) | change |",
        "|---|---|---|---|",
    ]
    for m, v in j["loso"].items():
        lines.append(f"| {m} | {v['rmst_rigid_mm']:.3f} | {v['rmst_rrbc_mm']:.3f} | {100 * v['change']:+.1f} % |")
    lines += [
        "",
        "## Candidate models, fitted to the points and scored",
        "",
        f"Selection: {j['selection']}. Predictions: {j['replicates']} simulated experiments of this layout per "
        "model (mean and 95 % range).",
        "",
        "| model | sizes | REML | AIC | CV log density | CV RMS (mm) | rigid RMS predicted (mm) | RRBC change predicted |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for m in j["models"]:
        p = m["predictions"]
        sizes = ", ".join(f"{k} {v:.3g}" for k, v in m["sizes"].items()) or "–"
        mark = " **(supported)**" if m["name"] == j["chosen"] else ""
        lines.append(
            f"| {m['name']}{mark} | {sizes} | {m['reml']:.1f} | {m['aic']:.1f} | {m['cv_log_density']:.1f} | "
            f"{m['cv_rms_mm']:.3f} | {p['rigid_rms_mm']['mean']:.3f} ({p['rigid_rms_mm']['lo95']:.3f}–"
            f"{p['rigid_rms_mm']['hi95']:.3f}) | {100 * p['rrbc_change']['mean']:+.1f} % "
            f"({100 * p['rrbc_change']['lo95']:+.1f} to {100 * p['rrbc_change']['hi95']:+.1f}) |"
        )
    lines += [
        "",
        f"![leave-one-site-out]({FIGURES[2]})",
        "",
        "Sizes: seating, smooth and flatness in mm (per axis; flatness RMS over the sites), kinematic in units of "
        "(0.1° joint offsets, 0.2 mm lengths, 0.05° twists), scale in units of 1000 ppm.",
        "",
    ]
    if j["joint_fit"] is not None:
        jf = j["joint_fit"]
        lines += [
            "## The Van Wyk tables and these points, fitted jointly",
            "",
            f"{jf['definition']}; {jf['replicates']} simulated experiments per direction for the tables. The same "
            "physical parameters must explain both data sets.",
            "",
            "| model | fit | parameters | tables' misfit | points' misfit | RRBC on the plate |",
            "|---|---|---|---|---|---|",
        ]
        for name, m in jf["models"].items():
            for fit in ("tables_only", "points_only", "joint"):
                f = m[fit]
                par = ", ".join(f"{k} {v:.3g}" for k, v in f["params"].items())
                gain = f"{100 * f['rrbc_change']:+.0f} %" if "rrbc_change" in f else "–"
                lines.append(
                    f"| {name} | {fit.replace('_', ' ')} | {par} | {f['deviance_tables']:.1f} | "
                    f"{f['deviance_points']:.1f} | {gain} |"
                )
        lines += ["", f"Chosen by the joint misfit: **{jf['chosen']}**.", ""]
    return "\n".join(lines)


def write_report(st: Study, out_dir, command: str) -> Path:
    j = st.to_json()
    return write_folder(
        out_dir,
        {
            FIGURES[0]: lambda p: _fig_residuals(st, p),
            FIGURES[1]: lambda p: _fig_variogram(st, p),
            FIGURES[2]: lambda p: _fig_loso(st, j, p),
            "report.md": lambda p: p.write_text(markdown(st, command, j), encoding="utf-8"),
            "summary.json": lambda p: p.write_text(json.dumps(json_safe(j), indent=1) + "\n", encoding="utf-8"),
        },
    )
