"""The simulated-annealing gap (issue 17, item 3): why Van Wyk & Marvel (2018) measured large SA gains that the
simulation of SA as published does not reproduce.

Measured (Table II): Small 3-point mean error 1.006 mm, SA Small 3-point 0.594 mm (ratio 0.590); Large 3-point
0.699, SA Large 3-point 0.435 (ratio 0.622). Simulated SA as published (cost Σ‖E_i‖² over the method's own
registration points, cooling 1/(2 ln τ), 5000 iterations, cost in m²) does nothing.

Hypotheses about what the experiment's SA did, each simulated on layout A (`reproduction`) from the same readings
as the 3-point frame it refines (common random numbers), under two error models — the one the CRPI points
support (per-site offsets 0.303 mm per axis + repeatability 0.096 mm, `rrbc reproduce crpi`) and the kinematic
model the Van Wyk tables were fitted with (0.47 x reference DH errors + 0.16 mm noise):

- ``as_published``  — the cost over the method's own 3 points in m² (the project's reading of the paper);
- ``mm_cost``       — the same cost in mm²: the schedule then rejects uphill moves and SA converges on the 3 points
  (a least-squares fit of them, in effect);
- ``averaged``      — SA on the 3 points with each reading the mean of 5 seatings (repeated readings averaged);
- ``all_sites``     — SA (mm²) whose cost sums over all 16 sites, one reading each: more points than the
  registration (as if the check readings entered the cost).

A hypothesis survives when the measured SA/plain ratio lies inside the 95 % range of the simulated ratio of mean
errors (over simulated experiments) for both the Small and the Large 3-point method, under a model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.simulation import batch
from rrbc_core.studies import reproduction as rp

MEASURED = {"small3": (1.006, 0.594), "large3": (0.699, 0.435)}  # Table II means: plain, SA (mm)
HYPOTHESES = ("as_published", "mm_cost", "averaged", "all_sites")
MODELS = {
    "crpi_seating": {"hole": 0.303, "noise": 0.096},
    "vanwyk_kinematic": {"kinematic": 0.47, "noise": 0.16},
}
REPEATS = 5  # seatings averaged in `averaged`


@dataclass(frozen=True)
class Outcome:
    model: str
    hypothesis: str
    data: str  # small3 or large3
    plain_mm: float  # mean error of the 3-point frame (mean over experiments)
    sa_mm: float
    ratio: tuple  # SA / plain: (mean, lo95, hi95) over experiments
    measured_ratio: float

    @property
    def consistent(self) -> bool:
        return self.ratio[1] <= self.measured_ratio <= self.ratio[2]


def _mean_error(a, t, q, sites_n) -> np.ndarray:
    back = np.linalg.solve(a[:, None], (q - t[:, None])[..., None])[..., 0]
    return np.linalg.norm(back - sites_n[None], axis=-1).mean(axis=1)


def _anneal(sensor, robot, unit: float, start) -> tuple[np.ndarray, np.ndarray]:
    """SA refining the 3-point frame (a0, t0) on these points, its cost evaluated in unit mm (1000: m²)."""
    a0, t0, seeds = start
    a, t = batch.annealing_batch(
        sensor / unit, robot / unit, seeds=seeds, iterations=rp.SA_ITERATIONS, initial=(a0, t0 / unit)
    )
    return a, t * unit


def run(replicates: int = 200, seed: int = 0) -> list[Outcome]:
    if not (10 <= int(replicates) <= 10_000):
        raise InputError(f"replicates must be from 10 to 10000, got {replicates}")
    lay = rp.layout_by_name("A")
    geo = rp.geometry_for(lay)
    truth = lay.points_robot[geo.slot_point]
    sites_n = lay.points_n[geo.check_point]
    out = []
    for mi, (mname, weights) in enumerate(MODELS.items()):
        fields = {c: rp.component_fields(geo, c, replicates, seed + 10 * mi) for c in weights}
        readings = truth[None] + sum(w * fields[c] for c, w in weights.items())
        # `averaged`: every reading the mean of REPEATS seatings - the same per-site and arm part, the noise averaged
        extra = np.random.default_rng([seed, mi, 7]).standard_normal((REPEATS - 1,) + readings.shape)
        averaged = readings + weights["noise"] * ((fields["noise"] + extra.sum(axis=0)) / REPEATS - fields["noise"])
        for k, data in enumerate(("small3", "large3")):
            idx = lay.registration[data]
            s = np.broadcast_to(lay.points_n[idx], (replicates, len(idx), 3))
            r = readings[:, geo.reg_slots[data][0]]
            a0, t0 = batch.three_point_batch(s, r)
            m = rp.METHODS.index("Small 3-point" if data == "small3" else "Large 3-point")
            q = readings[:, geo.check_slots[m]]
            plain = _mean_error(a0, t0, q, sites_n)
            seeds = rp.annealing_seeds(seed + mi, replicates)[k]

            first = geo.check_slots[m][:: rp.REPETITIONS]  # one reading of each of the 16 sites
            s16 = np.broadcast_to(lay.points_n[:16], (replicates, 16, 3))
            start = (a0, t0, seeds)
            variants = {
                "as_published": _anneal(s, r, rp.SA_COST_UNIT_MM, start),
                "mm_cost": _anneal(s, r, 1.0, start),
                "averaged": _anneal(s, averaged[:, geo.reg_slots[data][0]], 1.0, start),
                "all_sites": _anneal(s16, readings[:, first], 1.0, start),
            }
            for h, (a, t) in variants.items():
                sa = _mean_error(a, t, q, sites_n)
                ratio = sa / plain
                out.append(
                    Outcome(
                        mname,
                        h,
                        data,
                        float(plain.mean()),
                        float(sa.mean()),
                        (float(ratio.mean()), float(np.percentile(ratio, 2.5)), float(np.percentile(ratio, 97.5))),
                        MEASURED[data][1] / MEASURED[data][0],
                    )
                )
    return out
