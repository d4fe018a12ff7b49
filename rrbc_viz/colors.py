"""Colours of the browser app and the heat-map colour scale (display only: no RRBC numbers are made here).

Colours are RGB tuples of ints 0..255; arrays handed to viser are uint8 (floats would be read as 0..1).
"""

from __future__ import annotations

import numpy as np

Rgb = tuple[int, int, int]

REGISTRATION: Rgb = (150, 90, 220)
FIDUCIAL: Rgb = (255, 150, 30)
FIDUCIAL_EXCLUDED: Rgb = (150, 150, 150)
TARGET: Rgb = (20, 40, 110)
TARGET_EXTRAPOLATED: Rgb = (235, 30, 200)
CHECK: Rgb = (0, 100, 50)  # a measurement file's check rows (targets scored against their robot values)
CHECK_EXTRAPOLATED: Rgb = (120, 120, 0)  # a check outside the fiducials' hull: a check still, not a target
REGION: Rgb = (80, 170, 255)
HULL: Rgb = (240, 190, 40)
CORRECTION_FIDUCIAL: Rgb = (255, 110, 0)
CORRECTION_TARGET: Rgb = (0, 175, 255)
LAND_RIGID: Rgb = (213, 94, 0)
LAND_RRBC: Rgb = (0, 150, 170)
LAND_VEC: Rgb = (120, 70, 20)
LAND_ANCHOR: Rgb = (40, 40, 40)
LAND_STALK: Rgb = (110, 110, 110)
LAND_RING: Rgb = (60, 60, 60)
MODEL_INSIDE: Rgb = (95, 95, 95)  # a measured row inside its predicted 95 % region (Model tab)
MODEL_OUTSIDE: Rgb = (130, 0, 0)  # outside it
MODEL_MISFIT: Rgb = (25, 25, 25)  # measured minus predicted residual, magnified
BOUND: Rgb = (205, 170, 120)  # a target's 95 % bound (the "bounds" layer)
READING_SENSOR: Rgb = (30, 30, 30)  # a fiducial's sensor reading placed by (R, t) (lesson step 5)
READING_ROBOT: Rgb = CORRECTION_FIDUCIAL  # its robot reading: their offset is the fiducial's correction

#: The drag gizmo's axis colours (drei PivotControls' defaults in viser 1.1.1's client: x, y, z). Data colours
#: keep a CIE76 colour difference of at least MIN_GIZMO_DELTA_E from each (tests/viz check it).
GIZMO_AXES: tuple[Rgb, ...] = ((255, 32, 96), (32, 223, 128), (32, 128, 255))
MIN_GIZMO_DELTA_E = 30.0
#: The colours data are drawn in (those the legend names).
DATA_COLORS: dict[str, Rgb] = {
    "registration point": REGISTRATION,
    "fiducial": FIDUCIAL,
    "excluded fiducial": FIDUCIAL_EXCLUDED,
    "target": TARGET,
    "check (measured data)": CHECK,
    "target outside the hull (extrapolated)": TARGET_EXTRAPOLATED,
    "check outside the hull (extrapolated)": CHECK_EXTRAPOLATED,
    "region of variability": REGION,
    "95 % bound of a target (× arrows, or true size)": BOUND,
    "fiducials' hull": HULL,
    "correction at a fiducial": CORRECTION_FIDUCIAL,
    "correction at a target": CORRECTION_TARGET,
    "rigid landing": LAND_RIGID,
    "RRBC landing": LAND_RRBC,
    "VEC landing (Arm tab)": LAND_VEC,
    "truth (bullseye centre)": LAND_ANCHOR,
    "measured row inside its predicted region (Model tab)": MODEL_INSIDE,
    "measured row outside its predicted region (Model tab)": MODEL_OUTSIDE,
}
NO_VALUE: Rgb = (128, 128, 128)

#: The heat-map scale, low → high (viridis-like stops, perceptually ordered, colour-blind safe).
SCALE_STOPS = np.array([[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]], dtype=float)


def cie_lab(rgb) -> np.ndarray:
    """CIE L*a*b* (D65) of an sRGB colour (0..255)."""
    c = np.asarray(rgb, float) / 255.0
    c = np.where(c > 0.04045, ((c + 0.055) / 1.055) ** 2.4, c / 12.92)
    m = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
    xyz = m @ c / np.array([0.95047, 1.0, 1.08883])
    f = np.where(xyz > 0.008856, np.cbrt(xyz), 7.787 * xyz + 16.0 / 116.0)
    return np.array([116.0 * f[1] - 16.0, 500.0 * (f[0] - f[1]), 200.0 * (f[1] - f[2])])


def delta_e(a, b) -> float:
    """CIE76 colour difference of two sRGB colours (about 2.3 is just noticeable; 100 is black to white)."""
    return float(np.linalg.norm(cie_lab(a) - cie_lab(b)))


def legend_html(names=None) -> str:
    """The colour legend: a swatch and a name per data colour (inline HTML)."""
    items = DATA_COLORS if names is None else {k: DATA_COLORS[k] for k in names}
    chips = "".join(
        f'<span style="display:inline-block;margin:0 10px 2px 0;white-space:nowrap">'
        f'<span style="display:inline-block;width:0.8em;height:0.8em;border-radius:50%;background:{hex_color(c)};'
        f'vertical-align:middle;margin-right:4px;border:1px solid #888"></span>{name}</span>'
        for name, c in items.items()
    )
    return f'<div style="font-size:0.8em;line-height:1.5">{chips}</div>'


def hex_color(rgb) -> str:
    """'#rrggbb' for an RGB triple (0..255)."""
    r, g, b = (int(round(float(c))) for c in rgb)
    return f"#{r:02x}{g:02x}{b:02x}"


def scale_colors(values, lo: float, hi: float) -> np.ndarray:
    """Colours (N, 3) uint8 of `values` on the heat-map scale from lo to hi; NaN values are grey."""
    v = np.asarray(values, dtype=float).reshape(-1)
    span = hi - lo if hi > lo else 1.0
    t = np.clip((v - lo) / span, 0.0, 1.0)
    t = np.where(np.isfinite(t), t, 0.0)
    x = t * (len(SCALE_STOPS) - 1)
    knots = np.arange(len(SCALE_STOPS), dtype=float)
    out = np.stack([np.interp(x, knots, SCALE_STOPS[:, c]) for c in range(3)], axis=1)  # piecewise linear
    out[~np.isfinite(v)] = NO_VALUE
    return np.round(out).astype(np.uint8)


HEAT_NOTE = (
    "Ring around each target: the mean over its region of variability, visible from afar. Dots: the "
    "samples themselves, inside the region (zoom in, or raise View → Region zoom)."
)


def legend_markdown(title: str, lo: float, hi: float, unit: str = "mm", note: str = HEAT_NOTE) -> str:
    """A colour-scale legend: a gradient bar with its end values (markdown with inline HTML), then `note`."""
    stops = ", ".join(hex_color(c) for c in SCALE_STOPS)
    return (
        f"**{title}**\n\n"
        f'<div style="height:12px;border-radius:3px;background:linear-gradient(to right, {stops})"></div>\n\n'
        f"{lo:.4f} {unit} (low) → {hi:.4f} {unit} (high)" + (f"\n\n{note}" if note else "")
    )


# ------------------------------------------------------------------------------------------------ planning
GHOST: Rgb = (0, 210, 200)  # suggested fiducials (translucent ghost spheres)
GHOST_OPACITY = 0.6

#: The coverage scale, 0 (no part of the region inside the fiducials' hull) → 1 (all of it): red through yellow
#: to blue (ColorBrewer RdYlBu stops: readable with red-green colour blindness; full coverage is the blue end).
COVERAGE_STOPS = np.array(
    [[215, 48, 39], [252, 141, 89], [254, 224, 144], [145, 191, 219], [69, 117, 180]], dtype=float
)


def coverage_colors(values) -> np.ndarray:
    """Colours (N, 3) uint8 of coverage fractions on the coverage scale (0 red … 1 blue); NaN is grey."""
    v = np.asarray(values, dtype=float).reshape(-1)
    t = np.where(np.isfinite(v), np.clip(v, 0.0, 1.0), 0.0)
    x = t * (len(COVERAGE_STOPS) - 1)
    i = np.minimum(np.floor(x).astype(int), len(COVERAGE_STOPS) - 2)
    f = (x - i)[:, None]
    out = COVERAGE_STOPS[i] * (1.0 - f) + COVERAGE_STOPS[i + 1] * f
    out[~np.isfinite(v)] = NO_VALUE
    return np.round(out).astype(np.uint8)


def coverage_color(value: float) -> Rgb:
    r, g, b = (int(c) for c in coverage_colors([value])[0])
    return (r, g, b)


def coverage_legend_markdown() -> str:
    """The coverage legend: a gradient bar from 0 % to 100 % and what is coloured."""
    stops = ", ".join(hex_color(c) for c in COVERAGE_STOPS)
    return (
        "**Coverage**: the fraction of a target's region of variability inside the fiducials' hull (NIST's rule: "
        "all of it should be).\n\n"
        f'<div style="height:12px;border-radius:3px;background:linear-gradient(to right, {stops})"></div>\n\n'
        "0 % (red) → 100 % (blue). Coloured: each target's region (zoom in, or raise View → Region zoom) and a "
        "translucent halo around the target, visible from afar."
    )
