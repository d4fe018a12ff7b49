"""What the session hands the app besides an `Evaluation`: the heat map over the targets' regions (`HeatMap`), the
planning state (`PlanningState`), the Monte Carlo plots (`MonteCarloPlots`), the error model with the app's
noise and bias sizes applied (`scaled`), and which targets' corrections a fiducial's drag changed most
(`correction_changes`, `largest_changes`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from rrbc_core.analysis.planning_model import RmstPrediction


@dataclass(frozen=True, eq=False)
class HeatMap:
    """Samples (S,3) robot frame with their target, predicted errors rigid/RRBC (S,) mm (NaN without truth),
    the correction size (S,) mm, its gp std (S,) or None, extrapolation flags and the distance off the fiducials'
    plane."""

    positions: np.ndarray
    target: tuple
    error_rigid: np.ndarray
    error_rrbc: np.ndarray
    correction_mm: np.ndarray
    std_mm: np.ndarray | None
    extrapolated: np.ndarray
    off_plane_mm: np.ndarray | None = None  # (S,) from the fiducials' plane or line (0 for a 3-D set)


@dataclass(frozen=True, eq=False)
class PlanningState:
    """Planning for the fiducials as the session has them: per target (M,) the fraction of its region of
    variability inside the included fiducials' hull; the fast predicted RMST (planning.RmstPrediction: rigid_mm,
    rigid_std_mm, rrbc_mm, rrbc_std_mm, method) over the regions, None for measured data (no error model); the number of fiducials it counts."""

    target_ids: tuple
    coverage: np.ndarray
    predicted: RmstPrediction | None
    fiducials_used: int

    def coverage_of(self, pid: str) -> float:
        return float(self.coverage[self.target_ids.index(pid)])


@dataclass(frozen=True, eq=False)
class MonteCarloPlots:
    """Errors (T, C) mm at C check points over T trials, rigid and RRBC, and the checks' distances (C,)."""

    rigid: np.ndarray
    rrbc: np.ndarray
    distance: np.ndarray
    trials: int

    def histogram(self, bins: int = 30) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(bin centres, rigid counts, RRBC counts) on a shared range, as fractions of all samples."""
        hi = float(max(self.rigid.max(), self.rrbc.max(), 1e-9))
        edges = np.linspace(0.0, hi, bins + 1)
        a, _ = np.histogram(self.rigid.ravel(), edges)
        b, _ = np.histogram(self.rrbc.ravel(), edges)
        n = self.rigid.size
        return 0.5 * (edges[1:] + edges[:-1]), a / n, b / n

    def by_distance(self, bins: int = 8) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Error against distance from the scene's origin, binned: (bin centre (B,), mean rigid error (B,), mean RRBC
        error (B,), half-widths (B,) of their 95 % intervals), mm, over equal-count bins of the check points. The
        mean of a bin is over its check points and trials; its interval is 1.96 standard errors of the mean of the
        per-check-point means (trials average out the noise; the spread across check points is what varies)."""
        order = np.argsort(self.distance)
        groups = [g for g in np.array_split(order, min(int(bins), len(order))) if len(g)]
        centre = np.array([self.distance[g].mean() for g in groups])
        out = [centre]
        halves = []
        for err in (self.rigid, self.rrbc):
            per_check = err.mean(axis=0)
            out.append(np.array([per_check[g].mean() for g in groups]))
            halves.append(
                np.array([1.96 * per_check[g].std(ddof=1) / np.sqrt(len(g)) if len(g) > 1 else 0.0 for g in groups])
            )
        return out[0], out[1], out[2], halves[0], halves[1]


@dataclass(frozen=True)
class _Scaled:
    """An error term whose displacements are multiplied by `factor` (noise or bias size in the app)."""

    term: Any  # an error term (errormodels._Term)
    factor: float
    kind: str = field(default="")
    random: bool = field(default=False)

    def __post_init__(self):
        object.__setattr__(self, "kind", self.term.kind)
        object.__setattr__(self, "random", self.term.random)

    def sample(self, points, side, rng, trials):
        return self.factor * self.term.sample(points, side, rng, trials)

    def __getattr__(self, name):
        # a noise term's `covariance`, scaled with the term (absent, like here, if the term has none). Nothing else
        # is forwarded: an unscaled parameter read through the wrapper would be silently wrong.
        if name == "covariance" and hasattr(self.term, "covariance"):
            return lambda x: self.factor**2 * self.term.covariance(x)
        raise AttributeError(name)


def _scaled(model, noise: float, bias: float):
    """The model with random terms scaled by `noise` and deterministic ones by `bias`."""
    from rrbc_core.models.errormodels import ErrorModel

    def sc(t):
        f = noise if t.random else bias
        return t if f == 1.0 else _Scaled(t, f)

    return ErrorModel(robot=tuple(sc(t) for t in model.robot), sensor=tuple(sc(t) for t in model.sensor))


#: a target's correction changed "most" in a drag when its change is at least this share of the largest change
CHANGE_SHARE = 0.2
#: and at least this (mm): below it nothing is said to have changed
CHANGE_FLOOR_MM = 1e-3


def correction_changes(before_ids, before_corrections, ids, corrections) -> np.ndarray:
    """(T,) |ê_now − ê_before| mm of the targets `ids` (T,) with corrections (T, 3) (robot frame) against the
    corrections (B, 3) of `before_ids` (a drag's start); NaN for a target that was not there before."""
    before = {pid: np.asarray(c, float) for pid, c in zip(before_ids, np.asarray(before_corrections, float))}
    now = np.asarray(corrections, float).reshape(-1, 3)
    return np.array([float(np.linalg.norm(now[i] - before[p])) if p in before else np.nan for i, p in enumerate(ids)])


def largest_changes(ids, changes, k: int = 3) -> tuple[tuple[str, float], ...]:
    """The up to `k` targets (id, change mm) whose correction changed most, largest first: changes of at least
    CHANGE_SHARE of the largest and CHANGE_FLOOR_MM (what a fiducial's drag marks in the app)."""
    c = np.asarray(changes, float)
    ok = np.isfinite(c)
    if not np.any(ok):
        return ()
    top = float(np.max(c[ok]))
    if top < CHANGE_FLOOR_MM:
        return ()
    order = [i for i in np.argsort(-np.where(ok, c, -np.inf), kind="stable") if ok[i] and c[i] >= CHANGE_SHARE * top]
    return tuple((str(ids[i]), float(c[i])) for i in order[:k])
