"""The `compliance` error term (`rrbc_core.models.errorterms.Compliance`, masses in `rrbc_core.models.arm_masses`): a UR5 giving way under its own weight. Its
displacement is the first-order deflection −J(q)·(c τ(q)) (by the chain's own Jacobian), zero without compliance,
larger with a payload; a scene carrying it simulates through the real command, and RRBC corrects it where the
fiducials surround the targets."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest

from rrbc_core.models.arm_masses import dh_chain_with_masses
from rrbc_core.models.errormodels import PointSet
from rrbc_core.models.errorterms import Compliance, error_model_from_dict, error_model_to_dict
from rrbc_core.models.kinematics import UR5, UR5_TOOL_DOWN_SEED, forward
from rrbc_core.models.loads import gravity_loads
from tests.paths import RRBC, SCENES


def _points(n: int = 30):
    rng = np.random.default_rng(2)
    q = UR5_TOOL_DOWN_SEED + rng.normal(0, 0.3, (n, 6))
    p, rot = forward(UR5, q)
    return PointSet(robot=p, sensor=p, time=np.zeros(n), tool_rotation=rot, joint_seed=None)


def test_the_displacement_is_the_load_deflection():
    c = np.array([0.0, 3e-5, 2e-5, 1e-5, 0.0, 0.0])
    pts = _points()
    term = Compliance(tuple(c))
    d = term.displacement(pts)
    # first order: the joints the arm is at (IK of the points, as the term solves them) ...
    from rrbc_core.models.kinematics import inverse_path

    q = inverse_path(UR5, pts.robot, pts.tool_rotation, UR5_TOOL_DOWN_SEED)
    chain = dh_chain_with_masses(UR5)
    _, _, jq = chain.kinematics(q)
    tau = gravity_loads(chain, q).torque
    expected = -np.einsum("nij,nj->ni", jq, c * tau)
    assert np.sqrt(np.mean(np.sum(d**2, axis=1))) > 0.2  # a visible effect: tenths of a mm
    np.testing.assert_allclose(d, expected, atol=0.01 * np.abs(expected).max())
    assert np.abs(Compliance((0.0,) * 6).displacement(pts)).max() < 1e-8
    heavier = np.abs(Compliance(tuple(c), payload_kg=3.0).displacement(pts)).mean()
    assert heavier > 1.2 * np.abs(d).mean()


@pytest.mark.slow
def test_a_scene_carries_the_term(tmp_path):
    model = error_model_from_dict({"robot": [{"type": "compliance", "joints_rad_per_Nm": [0, 4e-5, 3e-5, 0, 0, 0]}]})
    assert error_model_from_dict(error_model_to_dict(model)) == model
    text = (SCENES / "demo_workcell.toml").read_text()
    start = text.index("[[error_model.robot]]")
    end = text.index("[[error_model.robot]]", start + 1) if text.count("[[error_model.robot]]") > 1 else None
    bent = text[:start] + '[[error_model.robot]]\ntype = "compliance"\njoints_rad_per_Nm = [0, 4e-5, 3e-5, 0, 0, 0]\n\n'
    bent += text[end:] if end is not None else text[text.index("\n[", start + 1) + 1 :]
    scene = tmp_path / "bent.toml"
    scene.write_text(bent)
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "demo_workcell.glb").write_bytes((SCENES / "meshes" / "demo_workcell.glb").read_bytes())

    def simulate(path):
        r = subprocess.run(
            [*RRBC, "simulate", path, "--trials", "40", "--json"], capture_output=True, text=True, timeout=300
        )
        assert r.returncode == 0, r.stderr
        return json.loads(r.stdout)["strategies"][0]

    from rrbc_core.io.scene_toml import load_scene

    loaded = load_scene(scene)
    assert loaded.error_model.robot[0].kind == "compliance"
    assert loaded.error_model.robot[0].dh.tool_mm == loaded.tool_mm  # the scene's arm and tool, as kinematic
    bent_run, demo_run = simulate(scene), simulate(SCENES / "demo_workcell.toml")
    # the bending arm is simulated (another bias than the demo's kinematic error), and RRBC corrects it there
    assert abs(bent_run["tre_rms_mm"] - demo_run["tre_rms_mm"]) > 0.1 * demo_run["tre_rms_mm"], (bent_run, demo_run)
    assert bent_run["rmst_rrbc_mm"] < 0.5 * bent_run["tre_rms_mm"], bent_run
