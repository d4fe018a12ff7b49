"""The one measurement model (`models.measurement`): its formula, and that the Monte Carlo, the session and the
planner read points through it alike."""

from __future__ import annotations

import numpy as np
import pytest

from rrbc_core.analysis import planning_model
from rrbc_core.io.scene_toml import load_scene
from rrbc_core.models.kinematics import tool_down
from rrbc_core.models.measurement import MeasurementModel
from rrbc_core.session.explorer import ExplorerSession
from rrbc_core.simulation.montecarlo import measure, work_cell_from_scene
from tests.paths import DEMO


@pytest.fixture(scope="module")
def scene():
    return load_scene(DEMO)


def test_readings_follow_the_documented_formula(scene):
    """s = T⁻¹p + b·β_s + n·ε, r = p + b·β_r + n·η, truth = p + b·β_r, with the model's own bias and noise."""
    rng = np.random.default_rng(3)
    p = rng.uniform([350, -150, 10], [600, 150, 80], (7, 3))
    base = MeasurementModel(scene.sensor_to_robot, scene.error_model, scene.joint_seed)
    scaled = MeasurementModel(
        scene.sensor_to_robot, scene.error_model, scene.joint_seed, bias_scale=2.5, noise_scale=0.3
    )
    pts = base.points(p, tool_down(0.0))
    bias_s, bias_r = base.bias(pts)
    assert np.abs(bias_r).max() > 1e-3  # the demo's kinematic bias is there
    noise = base.noise(pts, np.random.default_rng(5), trials=4)
    r = scaled.read(pts, noise=noise)
    np.testing.assert_allclose(r.truth, p + 2.5 * bias_r, atol=1e-12)
    np.testing.assert_allclose(
        r.sensor, scene.sensor_to_robot.apply_inverse(p)[None] + 2.5 * bias_s + 0.3 * noise[0], atol=1e-12
    )
    np.testing.assert_allclose(r.robot, (p + 2.5 * bias_r)[None] + 0.3 * noise[1], atol=1e-12)
    again = base.noise(pts, np.random.default_rng(5), trials=4)  # seeded: the same draws
    np.testing.assert_array_equal(again[0], noise[0])
    cov_s, cov_r = scaled.noise_covariance(pts)
    np.testing.assert_allclose(cov_s, 0.09 * base.noise_covariance(pts)[0])
    assert np.all(np.linalg.eigvalsh(cov_r) > 0)


def test_monte_carlo_session_and_planner_read_the_same_biased_points(scene):
    cell = work_cell_from_scene(scene, seed=0, checks_per_target=0, visibility=False)
    truth = measure(cell, np.random.default_rng(1), trials=2).truth
    planned = planning_model._readings(cell)
    np.testing.assert_allclose(planned.truth, truth, atol=1e-12)  # the planner's bias-only readings
    session = ExplorerSession.from_scene(scene)
    ids = list(cell.ids)
    for kind, group in (("registration", session.layout["registration"]), ("fiducials", session.layout["fiducials"])):
        expected = session.measure_points(kind, group.ids, group.positions, noise=False)
        for pid, t in zip(group.ids, expected.truth):
            np.testing.assert_allclose(t, truth[ids.index(pid)], atol=1e-9)
