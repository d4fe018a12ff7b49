"""Planning for measured data (rrbc_core.analysis.planning_coverage, ExplorerSession.coverage_plan): coverage
first, then spread, no error model."""

from __future__ import annotations

import numpy as np
import pytest

from rrbc_core.analysis.planning import coverage
from rrbc_core.analysis.planning_coverage import cube_regions, grid_candidates, suggest_by_coverage
from rrbc_core.errors import InputError
from rrbc_core.io.measurements import read_measurements
from rrbc_core.session import planning_view
from rrbc_core.session.explorer import ExplorerSession
from tests.paths import EXAMPLE_CSV


def test_the_greedy_choice_raises_coverage_to_full_then_spreads():
    rng = np.random.default_rng(7)
    targets = rng.uniform([0, 0, 0], [200, 200, 20], (6, 3))
    regions = cube_regions(targets, 4.0)
    flat = np.array([[-20, -20, 5], [220, -20, 5], [220, 220, 5], [-20, 220, 5.0]])  # coplanar: covers little
    before = coverage(flat, regions, samples_per_region=256, seed=0)
    cands = grid_candidates(targets, margin_mm=60.0, step_mm=40.0)
    idx, after = suggest_by_coverage(flat, regions, cands, 2, seed=0)
    assert np.all(after >= before - 1e-12) and np.all(after == 1.0) and before.mean() < 0.9
    # once everything is covered, further picks go far from what is there (spread)
    full = np.vstack([flat, cands[idx]])
    more, _ = suggest_by_coverage(full, regions, cands, 1, seed=0)
    d = np.linalg.norm(cands[:, None] - full[None], axis=2).min(axis=1)
    assert d[more[0]] == pytest.approx(d.max())
    with pytest.raises(InputError):
        suggest_by_coverage(flat, regions, cands[:1], 2)


def test_measured_sessions_plan_by_coverage():
    s = ExplorerSession.from_measurements(read_measurements(EXAMPLE_CSV))
    p0 = planning_view.coverage_plan(s, 0)
    assert len(p0.target_ids) == len(s.layout["targets"].ids) and p0.suggested.shape == (0, 3)
    p = planning_view.coverage_plan(s, 3)
    assert p.suggested.shape == (3, 3) and np.mean(p.coverage_after) > np.mean(p0.coverage)
    assert "grid" in p.candidate_source  # no mesh came with these data
