"""A URDF arm's own errors in a scene (`arm_errors`, issue 36 item 2) and `rrbc check-model` writing them.

A scene of our lift-column arm (a URDF: prismatic lift, six revolute joints) whose points are poses the arm reaches;
joint offsets and a joint-origin error of seeded random size are planted as an `arm_errors` term; `simulate` writes
the arm's joint columns (ROS units, the URDF's names) and its tool; check-model against the scene without the term
names `kinematic`, writes `arm_errors` from calibrate's identification, predicts held-out rows better, and the
extended model's intervals hold further files of the same points drawn with other noise about 95 % of the time."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import stats

from rrbc_core.analysis.scene_check import check_scene_model
from rrbc_core.analysis.scene_prediction import at_physical_points, file_stations, measured_figures, predict
from rrbc_core.io.joints import file_tool, joint_values
from rrbc_core.io.scene_toml import load_scene
from rrbc_core.models.armterms import ArmErrors
from rrbc_core.models.urdf import load_urdf
from rrbc_core.simulation.arm_data import random_poses
from rrbc_core.simulation.datasets import measured_data
from rrbc_core.simulation.montecarlo import work_cell_from_scene


def _points(kind: str, prefix: str, positions, region: bool = False) -> str:
    out = []
    for i, x in enumerate(positions):
        out.append(f'[[{kind}]]\nid = "{prefix}{i + 1}"\nposition = [{x[0]:.3f}, {x[1]:.3f}, {x[2]:.3f}]')
        if region:
            out.append('region = { kind = "sphere", radius = 2.0 }')
    return "\n".join(out)


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    """(base scene, planted scene, the planted parameters): 8 registration points, 28 fiducials and 12 targets at
    poses the lift arm reaches, a motion-capture sensor 0.02 mm, the arm's encoders 0.02 mm."""
    import trimesh

    d = tmp_path_factory.mktemp("lift")
    (d / "meshes").mkdir()
    trimesh.creation.box(extents=(100, 100, 10)).export(d / "meshes" / "floor.glb")
    chain = load_urdf("lift_arm")
    p = chain.forward(random_poses(chain, np.random.default_rng(3), 48))
    centre = p.mean(axis=0)
    text = "\n\n".join(
        [
            '[scene]\nname = "lift arm cell"\nunits = "mm"\nmesh = "meshes/floor.glb"',
            '[robot]\nmodel = "none"\ntool_mm = 0.0\nurdf = "lift_arm"',
            f'[sensor]\nkind = "mocap"\nposition = [4000, 3000, 2500]\nlook_at = [{centre[0]:.1f}, {centre[1]:.1f}, '
            f"{centre[2]:.1f}]",
            _points("registration", "R", p[:8]),
            _points("fiducial", "F", p[8:36]),
            _points("target", "T", p[36:48], region=True),
            '[[error_model.robot]]\ntype = "isotropic_noise"\nsigma_mm = 0.02',
            '[[error_model.sensor]]\ntype = "isotropic_noise"\nsigma_mm = 0.02',
            "[simulation]\ncheck_points_per_target = 3",
        ]
    )
    (d / "base.toml").write_text(text)
    base = load_scene(d / "base.toml")
    rng = np.random.default_rng(3690)
    planted_params = {
        "shoulder_joint.offset": float(rng.choice([-1, 1]) * rng.uniform(0.001, 0.004)),
        "forearm_joint.offset": float(rng.choice([-1, 1]) * rng.uniform(0.001, 0.004)),
        "upper_arm_joint.x": float(rng.choice([-1, 1]) * rng.uniform(0.5, 2.0)),
    }
    term = ArmErrors(parameters=planted_params).on_arm(urdf="lift_arm")
    planted = dataclasses.replace(base, error_model=base.error_model.extended(robot=[term]))
    return base, planted, planted_params


@pytest.mark.slow
def test_a_planted_arm_error_is_named_written_as_arm_errors_and_predicts(cell):
    base, planted, _ = cell
    work = work_cell_from_scene(planted, seed=0)
    m = measured_data(work, 11)
    chain = load_urdf("lift_arm")
    assert set(chain.columns) <= set(m.extra) and file_tool(m) == (0.0, 0.0, 0.0)  # simulate's columns
    r = check_scene_model(m, base, trials=100, folds=4, seed=0)
    assert "kinematic" in {e.name for e in r.unexplained}, [e.name for e in r.unexplained]
    assert "joint configuration" in r.follows
    arm = [t for t in r.added if t.table["type"] == "arm_errors"]
    assert len(arm) == 1 and arm[0].table["parameters"], [t.table["type"] for t in r.added]
    g = r.gain
    assert g["prediction_error_after_mm"] < 0.5 * g["prediction_error_before_mm"], g
    assert g["coverage_after"] > g["coverage_before"], g
    # further files of the same points, other noise: the extended model's intervals hold them
    n, inside = 4, np.zeros(2, int)
    for k in range(n):
        m2 = measured_data(work, 200 + k)
        st = at_physical_points(m2, file_stations(m2, "none", 0.0, joint_values(m2, chain)), r.extended_model)
        meas, pred = measured_figures(m2, st), predict(m2, st, r.extended_model, 200, k)
        for j, (arr, mine) in enumerate(((pred.fre, meas.fre), (pred.rmst_rigid, meas.rmst_rigid))):
            lo, hi = np.quantile(arr, [0.025, 0.975])
            inside[j] += int(lo <= mine[0] <= hi)
    assert np.all(inside >= stats.binom.ppf(0.001, n, 0.95)), inside


def test_the_term_is_what_the_arm_reports_less_where_it_is(cell):
    """With the file's joints: FK_nominal(q) − FK_true(q). Without them: joints that put the TRUE arm on the point
    (a redundant arm has many; the solver's within 0.01 mm), and FK_nominal of those joints less the point."""
    _, planted, params = cell
    term = next(t for t in planted.error_model.robot if isinstance(t, ArmErrors))
    chain = term.chain
    delta = np.array([params.get(n, 0.0) for n in chain.param_names])
    q = random_poses(chain, np.random.default_rng(5), 6)
    from rrbc_core.models.errormodels import PointSet

    true = chain.kinematics(q, delta, jacobians=False)[0]
    with_q = term.displacement(PointSet(true, true, np.zeros(6), joints=q))
    assert np.allclose(with_q, chain.forward(q) - true, atol=1e-9)
    pts = PointSet(true, true, np.zeros(6))
    solved = term.joints(pts)
    assert np.allclose(chain.kinematics(solved, delta, jacobians=False)[0], true, atol=0.02)
    assert np.allclose(term.displacement(pts), chain.forward(solved) - true, atol=1e-9)


def test_a_bad_arm_errors_term_is_refused_with_its_reason(tmp_path):
    from rrbc_core.errors import InputError

    with pytest.raises(InputError, match="not a parameter"):
        ArmErrors(parameters={"elbow.offset": 0.1}).on_arm(urdf="lift_arm")
    with pytest.raises(InputError, match="finite number"):
        ArmErrors(parameters={"shoulder_joint.offset": float("nan")})
    with pytest.raises(InputError, match="needs the scene's arm|has no arm"):
        ArmErrors(parameters={}).chain  # noqa: B018
