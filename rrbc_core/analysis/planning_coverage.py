"""Planning without an error model (measured data): where to measure more fiducials so that every target's region
lies inside the fiducials' hull — coverage first, then spread.

Measured targets carry no region of variability; each gets a cube of `DEFAULT_REGION_MM` (the scene format's and
`rrbc scene new`'s default) about its place. Candidates: points on the cell mesh's upward surfaces around the
targets, seen from the sensor (when a mesh is given; `authoring.cell_geometry`), else a grid around the targets
(free space, said so). The greedy choice adds, one at a time, the candidate that most raises the mean coverage
(`planning.coverage`, the fraction of each region inside the hull); ties (e.g. once everything is covered) go to
the candidate farthest from the fiducials so far (spread). Robot frame, mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core.errors import InputError

DEFAULT_REGION_MM = 4.0
MAX_CANDIDATES = 300
COVERAGE_SAMPLES = 256


@dataclass(frozen=True, eq=False)
class CoveragePlan:
    """target_ids (T,), coverage / coverage_after (T,) fractions, suggested (K, 3) mm with suggested_ids, and where
    the candidates came from (`candidate_source`, text) and how many there were."""

    target_ids: tuple
    coverage: np.ndarray
    suggested_ids: tuple
    suggested: np.ndarray
    coverage_after: np.ndarray
    candidate_source: str
    n_candidates: int


def cube_regions(positions, edge_mm: float = DEFAULT_REGION_MM) -> list:
    """A cubic region of `edge_mm` (full edge) about each position (T, 3)."""
    from rrbc_core.io.scene import Region

    return [Region("box", np.asarray(p, float), np.full(3, float(edge_mm))) for p in np.asarray(positions, float)]


def grid_candidates(targets, margin_mm: float = 150.0, step_mm: float = 50.0) -> np.ndarray:
    """A grid over the targets' box widened by `margin_mm` on every side, at most MAX_CANDIDATES points."""
    t = np.asarray(targets, float).reshape(-1, 3)
    lo, hi = t.min(0) - margin_mm, t.max(0) + margin_mm
    axes = [np.arange(lo[i], hi[i] + 1e-9, step_mm) for i in range(3)]
    g = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    if len(g) > MAX_CANDIDATES:
        g = g[np.linspace(0, len(g) - 1, MAX_CANDIDATES).astype(int)]
    return g


def suggest_by_coverage(fiducials, regions, candidates, k: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Indices (K,) of `candidates` (C, 3) to add to `fiducials` (N, 3), and the coverage (T,) after (module
    docstring)."""
    from rrbc_core.analysis.planning import coverage

    f = np.asarray(fiducials, float).reshape(-1, 3)
    c = np.asarray(candidates, float).reshape(-1, 3)
    k = int(k)
    if not 1 <= k <= 50:
        raise InputError(f"the number of fiducials to suggest must be from 1 to 50, got {k}")
    if len(c) < k:
        raise InputError(f"only {len(c)} candidate locations for {k} fiducials")
    chosen: list[int] = []
    cov = (
        coverage(f, regions, samples_per_region=COVERAGE_SAMPLES, seed=seed) if len(f) >= 4 else np.zeros(len(regions))
    )
    for _ in range(k):
        current = np.vstack([f, c[chosen]]) if chosen else f
        d = np.linalg.norm(c[:, None, :] - current[None], axis=2).min(axis=1) if len(current) else np.ones(len(c))
        best, best_key = -1, None
        for i in range(len(c)):
            if i in chosen:
                continue
            trial = np.vstack([current, c[i]])
            score = (
                float(np.mean(coverage(trial, regions, samples_per_region=COVERAGE_SAMPLES, seed=seed)))
                if len(trial) >= 4
                else 0.0
            )
            key = (round(score, 6), float(d[i]))
            if best_key is None or key > best_key:
                best, best_key = i, key
        chosen.append(best)
    final = np.vstack([f, c[chosen]])
    after = coverage(final, regions, samples_per_region=COVERAGE_SAMPLES, seed=seed) if len(final) >= 4 else cov
    return np.array(chosen, int), np.asarray(after, float)
