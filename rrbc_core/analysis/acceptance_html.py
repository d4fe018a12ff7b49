"""`rrbc report`'s HTML: one self-contained page from the acceptance object (`analysis.acceptance`).

No external request: the figures are matplotlib PNGs inlined as data URIs, the style is inline CSS, and there is no
script. It prints to PDF from a browser (figures and tables avoid page breaks inside them). Every string from the
file (ids, station names, the source's name) is HTML-escaped.
"""

from __future__ import annotations

import base64
import io
from html import escape

import numpy as np

from rrbc_core.analysis.acceptance import METHOD_NAMES

COLOURS = {"rigid": "#8c8c8c", "rrbc": "#0077bb", "vec": "#cc6600", "vec_rrbc": "#7a3b99"}
VERDICT_COLOURS = {"PASS": "#1a7f37", "FAIL": "#b42318", "UNDECIDED": "#6b6b6b"}
STYLE = """
body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;max-width:62rem;margin:1.5rem auto;padding:0 1rem;
color:#222;line-height:1.45}
h1{font-size:1.6rem;margin-bottom:.2rem}h2{font-size:1.2rem;margin-top:1.8rem;border-bottom:1px solid #ddd}
table{border-collapse:collapse;margin:.5rem 0;font-size:.9rem}td,th{border:1px solid #ddd;padding:.25rem .5rem;
text-align:right}th{background:#f4f4f4}td.l,th.l{text-align:left}tr.fail td{background:#fde8e6}
.verdict{font-size:1.5rem;font-weight:700;padding:.6rem 1rem;border-radius:.4rem;color:#fff;display:inline-block}
.muted{color:#666;font-size:.9rem}img{max-width:100%}figure{margin:.8rem 0;break-inside:avoid}
table,figure{break-inside:avoid}@media print{body{margin:0;max-width:none}h2{break-after:avoid}}
"""


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("rrbc")
    except PackageNotFoundError:  # pragma: no cover - run from a source tree without installing
        return "(source tree)"


def _instrument_words(inst: dict) -> str:
    """The instrument's reading noise in words: its figures and where they came from."""
    if inst.get("kind") == "polar":
        figs = (
            f"distance {inst.get('distance_mm', 0):g} mm + {inst.get('distance_ppm', 0):g} ppm, "
            f"angle {inst.get('angle_urad', 0):g} µrad"
        )
    else:
        figs = f"σ {_mm(inst.get('sigma_mm'))} mm per axis"
    name = inst.get("name", "")
    prefix = "" if name in ("estimated", "given") else f"{name}: "
    return f"{prefix}{figs} ({inst.get('source', '')})"


def _mm(v) -> str:
    return "—" if v is None or not np.isfinite(v) else f"{v:.3f}"


def _beyond(v, tolerance) -> str:
    """A failing figure (mm) with as many decimals (3 to 6) as it takes to read it beyond the tolerance (0.0501, not
    0.050 against 0.05)."""
    for digits in range(3, 7):
        if tolerance is None or round(float(v), digits) > float(tolerance):
            return f"{float(v):.{digits}f}"
    return f"{float(v):.6g}"


def _method_words(name: str, fig: dict) -> str:
    """A method's name for the table: RRBC with its interpolation and options (`interpolation` in correct's JSON)."""
    interp = fig.get("interpolation")
    if name != "rrbc" or not isinstance(interp, dict) or not interp.get("method"):
        return METHOD_NAMES[name]
    opts = ", ".join(
        f"{k.replace('_', ' ')} {v:g}" if isinstance(v, float) else f"{k.replace('_', ' ')} {v}"
        for k, v in interp.items()
        if k not in ("method", "chosen", "candidates") and v is not None and not isinstance(v, (dict, list))
    )
    chosen = interp.get("chosen")
    method = str(interp["method"]) + (f": {chosen}" if isinstance(chosen, str) else "")
    return f"{METHOD_NAMES[name]} ({escape(method)}{', ' + escape(opts) if opts else ''})"


def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def figures(acc: dict) -> list[tuple[str, str]]:
    """(caption, PNG data URI) of the report's figures: the checks' errors before and after (histograms), and the
    errors and targets' bounds against the distance to the nearest fiducial. [] without checks or targets."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rec = acc["recommended"]
    shown = ["rigid"] + ([rec] if rec != "rigid" else ["rrbc"])
    checks = [p for p in acc["points"] if p["role"] == "check" and p["error_mm"]]
    targets = [p for p in acc["points"] if p["role"] == "target"]
    out = []
    if checks:
        fig, ax = plt.subplots(figsize=(7.0, 3.2))
        errs = {m: np.array([p["error_mm"].get(m, np.nan) for p in checks], float) for m in shown}
        top = max(float(np.nanmax(e)) for e in errs.values() if np.isfinite(e).any())
        bins = np.linspace(0.0, top * 1.05 if top > 0 else 1.0, 21).tolist()
        for m in shown:
            e = errs[m][np.isfinite(errs[m])]
            ax.hist(e, bins=bins, alpha=0.55, color=COLOURS[m], label=f"{METHOD_NAMES[m]} (RMS {_mm(_rms(e))} mm)")
        if acc["tolerance_mm"] is not None:
            ax.axvline(acc["tolerance_mm"], color="#b42318", ls="--", label=f"tolerance {acc['tolerance_mm']:g} mm")
        ax.set_xlabel("3-D error at the checks (mm)")
        ax.set_ylabel("checks")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
        out.append((f"The {len(checks)} checks' errors, before ({METHOD_NAMES['rigid']}) and after", _png(fig)))
        plt.close(fig)
    if checks or targets:
        fig, ax = plt.subplots(figsize=(7.0, 3.2))
        for m in shown:
            d = [p["nearest_fiducial_mm"] for p in checks]
            e = [p["error_mm"].get(m) for p in checks]
            ax.scatter(d, e, s=14, color=COLOURS[m], label=f"check error, {METHOD_NAMES[m]}")
        tb = [(p["nearest_fiducial_mm"], (p["bound95_mm"] or {}).get(rec)) for p in targets]
        tb = [(d, b) for d, b in tb if d is not None and b is not None]
        if tb:
            td, tbd = np.array([d for d, _ in tb], float), np.array([b for _, b in tb], float)
            ax.scatter(td, tbd, s=30, marker="^", color="#222", label=f"target 95 % bound, {METHOD_NAMES[rec]}")
        if acc["tolerance_mm"] is not None:
            ax.axhline(acc["tolerance_mm"], color="#b42318", ls="--", label="tolerance")
        ax.set_xlabel("distance to the nearest fiducial (mm, sensor frame)")
        ax.set_ylabel("mm")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
        out.append(("Error and bound against the distance to the nearest fiducial", _png(fig)))
        plt.close(fig)
    return out


def _rms(e) -> float | None:
    e = np.asarray(e, float)
    e = e[np.isfinite(e)]
    return float(np.sqrt(np.mean(e**2))) if len(e) else None


def _table(head: list[str] | None, rows: list[list[str]], left: int = 1, classes: list[str] | None = None) -> str:
    """An HTML table (no header row when `head` is None); the first `left` columns left-aligned."""
    th = "".join(f'<th class="{"l" if i < left else ""}">{h}</th>' for i, h in enumerate(head or []))
    body = []
    for k, r in enumerate(rows):
        cls = f' class="{classes[k]}"' if classes and classes[k] else ""
        body.append(
            f"<tr{cls}>" + "".join(f'<td class="{"l" if i < left else ""}">{c}</td>' for i, c in enumerate(r)) + "</tr>"
        )
    return f"<table>{f'<tr>{th}</tr>' if head else ''}{''.join(body)}</table>"


def report_html(acc: dict, title: str = "RRBC acceptance report") -> str:
    """The whole page (module docstring)."""
    rec = acc["recommended"]
    v = acc["verdict"]
    m = acc["measured"]
    parts = [
        f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>{escape(title)}</title>"
        f"<style>{STYLE}</style></head><body>",
        f"<h1>{escape(title)}</h1><p class='muted'>{escape(str(m['source']))}</p>",
        f"<p><span class='verdict' style='background:{VERDICT_COLOURS[v]}'>{v}</span></p>",
        f"<p><b>Criterion:</b> {escape(acc['criterion'])}"
        + (f" ({acc['tolerance_mm']:g} mm)" if acc["tolerance_mm"] is not None else "")
        + f". <b>{escape(acc['reason'])}</b>.</p>",
    ]
    if acc["failing"]:
        grouped = any(f["group"] is not None for f in acc["failing"])
        rows = [
            [escape(f["id"]), f["role"]]
            + ([escape(str(f["group"] or ""))] if grouped else [])
            + ["95 % bound" if f["what"] == "bound95" else "error", _beyond(f["mm"], acc["tolerance_mm"])]
            for f in acc["failing"]
        ]
        head = ["point", "role"] + (["station"] if grouped else []) + ["what", "mm"]
        parts.append("<h2>Points beyond the tolerance</h2>" + _table(head, rows, len(head) - 1))
    parts.append("<h2>What was measured</h2>")
    inst = m["instrument"] or {}
    rows = [
        ["rows", str(m["rows"])],
        ["stations", escape(", ".join(map(str, m["stations"]))) if m["stations"] else "one"],
        ["fiducials", str(m["fiducials"])],
        ["targets", str(m["targets"])],
        ["checks", str(m["checks"])],
        ["instrument noise", escape(_instrument_words(inst))],
        ["arm model", escape(str(m["arm"])) if m["arm"] else "none given"],
    ]
    parts.append(_table(None, rows, 2))
    parts.append("<h2>Registration (robot = R · sensor + t)</h2>")
    rows = []
    arm = acc.get("arm_transform")
    arm_rows = [] if arm is None else ([arm] if isinstance(arm, dict) else list(arm))
    for r in list(acc["registration"]) + [{**a, "method": "VEC: identified with the arm"} for a in arm_rows]:
        xyz = r.get("xyz_mm")
        rpy = r.get("rpy_rad")
        rows.append(
            [
                escape(str(r.get("group") or "—")),
                escape(r["method"]),
                _mm(r.get("fre_rms_mm")),
                ", ".join(f"{x:.3f}" for x in xyz) if xyz else "—",
                ", ".join(f"{x:.6f}" for x in rpy) if rpy else "—",
            ]
        )
    head = [
        "station",
        "method",
        "fit residual at the registration points, RMS (mm)",
        "translation xyz (mm)",
        "rotation roll, pitch, yaw (rad, URDF convention)",
    ]
    parts.append(_table(head, rows, 2))
    parts.append("<h2>Methods side by side</h2>")
    with_cv = any(fig.get("cv_rmst_mm") is not None for fig in acc["methods"].values())
    rows = []
    for name, fig in acc["methods"].items():
        rms = fig.get("calibrate_rmst_mm", fig.get("rmst_mm"))
        row = [_method_words(name, fig) + (" (recommended)" if name == rec else ""), _mm(rms)]
        rows.append(row + ([_mm(fig.get("cv_rmst_mm"))] if with_cv else []))
    head = ["method", "RMS at the checks (mm)"] + (["cross-validated over the fiducials (mm)"] if with_cv else [])
    parts.append(_table(head, rows, 1))
    parts.append(f"<p><b>Recommended: {METHOD_NAMES[rec]}.</b> {escape(acc['recommendation_basis'])}</p>")
    for caption, uri in figures(acc):
        parts.append(
            f"<figure><img alt='{escape(caption)}' src='{uri}'><figcaption class='muted'>{escape(caption)}"
            "</figcaption></figure>"
        )
    parts.append("<h2>Every point</h2>")
    failing = {(f["id"], f["group"]) for f in acc["failing"]}
    stations = any(p["group"] is not None for p in acc["points"])
    rows, classes = [], []
    for p in acc["points"]:
        err = p["error_mm"] or {}
        b = (p["bound95_mm"] or {}).get(rec)
        row = [escape(p["id"]), p["role"]] + ([escape(str(p["group"]))] if stations else [])
        row += [
            _mm(err.get("rigid")),
            _mm(err.get(rec)),
            _mm(p["correction_mm"]),
            _mm(b),
            _mm(p["nearest_fiducial_mm"]),
            "yes" if p["extrapolated"] else "no",
        ]
        if rec != "rigid":
            row.append("worse" if err and err.get(rec, 0.0) > err.get("rigid", np.inf) else "")
        rows.append(row)
        classes.append("fail" if (p["id"], p["group"]) in failing else "")
    head = ["point", "role"] + (["station"] if stations else [])
    head += [
        "error rigid",
        f"error {METHOD_NAMES[rec]}",
        "size of the RRBC correction",
        f"95 % bound ({METHOD_NAMES[rec]})",
        "nearest fiducial",
        "outside the fiducials' hull",
    ]
    head += [f"{METHOD_NAMES[rec]} worse than rigid"] if rec != "rigid" else []
    parts.append(
        "<p class='muted'>mm. Errors only where the file holds the truth (checks); a check passes or fails by its "
        "error, a target by its 95 % bound (the distance within which its corrected position lies with 95 % "
        "probability).</p>"
    )
    parts.append(_table(head, rows, 3 if stations else 2, classes))
    d = acc["diagnosis"]
    parts.append("<h2>What the data hold beyond a rigid transform and noise (rrbc diagnose)</h2>")
    if d["effects"]:
        parts.append(
            "<ul>"
            + "".join(f"<li><b>{escape(k)}</b>: {escape(str(e))}</li>" for k, e in d["effects"].items())
            + "</ul>"
        )
    else:
        parts.append("<p>Nothing beyond a rigid transform plus isotropic noise.</p>")
    if d["limits"]:
        parts.append("<p class='muted'>Limits: " + escape("; ".join(d["limits"])) + "</p>")
    if acc["warnings"]:
        parts.append("<h2>Warnings</h2><ul>" + "".join(f"<li>{escape(w)}</li>" for w in acc["warnings"]) + "</ul>")
    parts.append(
        f"<p class='muted'>Made by rrbc {escape(_version())} (rrbc report); every figure is the one rrbc correct, "
        "rrbc diagnose and rrbc calibrate print for this file.</p></body></html>"
    )
    return "\n".join(parts)
