"""The breadboard of Van Wyk & Marvel (2018) as the reproduction assumes it: four layouts (A–D) of the 16 test sites,
the registration points of each method and the breadboard-to-robot placement, since the paper gives them only in a
figure (docs/reference/vanwyk2018.md)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.geometry.transforms import RigidTransform

REPETITIONS = 5  # per site: 16 x 5 = 80 samples per method (Table I implies 79-80)
TOOL_MM = 100.0  # stylus length (assumption, as in scenes/breadboard_vanwyk2018.toml)


# ------------------------------------------------------------------------------------------------------
# Layouts
# ------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Layout:
    """One reading of the paper's Fig. 1: where the sites, registration points, N's origin and the robot are.

    points_n: (17, 3) mm in frame N, rows 0..15 the test sites S1..S16 (row-major), row 16 the 5th point P5.
    registration: {"small3" | "large3" | "large5" | "cluster": row indices} (small3/large3: p1 origin, p2 x).
    n_to_robot: robot = R @ N + t (the robot base at the robot-frame origin, z up).
    """

    name: str
    description: str
    points_n: np.ndarray
    registration: dict
    n_to_robot: RigidTransform
    assumptions: tuple
    registrations: int = 1  # registrations per method and experiment; repetition l uses l mod this

    @property
    def sites_n(self) -> np.ndarray:
        return self.points_n[:16]

    @property
    def points_robot(self) -> np.ndarray:
        return self.n_to_robot.apply(self.points_n)


def _grid(xs, ys, z=11.0) -> np.ndarray:
    return np.array([[x, y, z] for y in ys for x in xs], dtype=float)


def _n_to_robot(base_n) -> RigidTransform:
    """N x = −robot y, N y = +robot x (robot facing the plate across its long side), base at N = base_n."""
    rot = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    return RigidTransform(rot, -rot @ np.asarray(base_n, dtype=float))


def _layout(name, description, sites, p5, small3, base_n, extra) -> Layout:
    pts = np.vstack([sites, np.asarray(p5, dtype=float)[None]])
    corners = [0, 3, 12, 15]
    common = (
        "16 sites x 5 repetitions = 80 samples per method (Table I's r and p imply 79-80)",
        "one registration per method and experiment; SA variants refine their base registration from the same readings",
        f"robot: UR5 (CB3) DH, {TOOL_MM:.0f} mm stylus pointing down, base level with the plate",
        "SA: published cooling T = 1/(2 ln tau), 5000 iterations, cost in m^2 (steps scale with the initial misfit)",
        "clustering: k-means (2 clusters) on the 4 corners, each cluster borrows its nearest point (project's reading of eqs. 16-17)",
        "peg test (Table III) sees the same error distribution as Table II; 160 tries = 16 sites x 10",
    )
    return Layout(
        name=name,
        description=description,
        points_n=pts,
        registration={"small3": list(small3), "large3": [0, 3, 12], "large5": corners + [16], "cluster": corners},
        n_to_robot=_n_to_robot(base_n),
        assumptions=tuple(extra) + common,
    )


def layouts() -> tuple[Layout, ...]:
    """Plausible readings of Fig. 1 and of the protocol (A is the one in scenes/breadboard_vanwyk2018.toml):
    B and C move the robot, N's origin, the sites and P5; D keeps A's geometry but registers once per
    repetition instead of once per method."""
    xs, ys = (50.0, 300.0, 550.0, 800.0), (25.0, 200.0, 375.0, 550.0)
    a = _layout(
        "A",
        "4x4 sites = registration grid over 750 x 525 mm; N at the plate's corner hole; robot 150 mm from the near row",
        _grid(xs, ys),
        (425.0, 150.0, 11.0),
        (0, 1, 4),
        (425.0, -125.0, 0.0),
        (
            "sites: regular 4x4 grid at N x = 50..800 step 250, y = 25..550 step 175 (z = 11 mm); registration corners = corner sites",
            "origin of N: centre of the plate's corner hole next to site S1",
            "small 3-point: S1 (origin), S2 (x), S5 - the 250 x 175 mm corner next to N's origin",
            "5th point P5 at N = (425, 150, 11), off-centre, not collinear with corners",
            "robot base at N = (425, -125, 0): centred on the 750 mm side, 150 mm before the first row",
        ),
    )
    b = _layout(
        "B",
        "as A, but the robot across the plate (150 mm beyond the far row) and P5 mirrored",
        _grid(xs, ys),
        (375.0, 400.0, 11.0),
        (0, 1, 4),
        (425.0, 700.0, 0.0),
        (
            "sites: as A; origin of N at the corner hole next to S1, now on the side AWAY from the robot",
            "small 3-point: S1, S2, S5",
            "5th point P5 at N = (375, 400, 11)",
            "robot base at N = (425, 700, 0): centred on the 750 mm side, 150 mm beyond the far row",
        ),
    )
    c = _layout(
        "C",
        "sites inset inside the registration rectangle (175 x 150 mm grid), robot shifted sideways",
        _grid((125.0, 300.0, 475.0, 650.0), (75.0, 225.0, 375.0, 525.0)),
        (550.0, 300.0, 11.0),
        (0, 1, 4),
        (300.0, -125.0, 0.0),
        (
            "sites: 4x4 grid at N x = 125..650 step 175, y = 75..525 step 150, inside the registration rectangle",
            "registration corners: the sites' corner holes S1, S4, S13, S16 (so the large rectangle is 525 x 450 mm here)",
            "small 3-point: S1, S2, S5 (175 x 150 mm), next to N's origin",
            "5th point P5 at N = (550, 300, 11), 139 mm from both diagonals",
            "robot base at N = (300, -125, 0): 125 mm off the plate's centre line",
        ),
    )
    d = Layout(
        name="D",
        description="as A, but each of the 5 repetitions has its own registration (5 per method and experiment)",
        points_n=a.points_n,
        registration=a.registration,
        n_to_robot=a.n_to_robot,
        assumptions=(
            "as layout A, except: every repetition (16 sites) follows its own registration from fresh readings, "
            "so each method's 80 samples come from 5 registrations",
        )
        + tuple(x for x in a.assumptions if not x.startswith("one registration per method")),
        registrations=REPETITIONS,
    )
    return (a, b, c, d)


def _by_name(items, name: str, what: str):
    for item in items:
        if item.name == name:
            return item
    raise InputError(f"unknown {what} {name!r}; choose one of {', '.join(i.name for i in items)}")


def layout_by_name(name: str) -> Layout:
    return _by_name(layouts(), name, "layout")
