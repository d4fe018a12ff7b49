"""One coverage (issue 25, item 2): inside or outside the fiducials' hull is the same verdict from every caller —
`interpolation.hull.assess_coverage`, `rrbc correct` (text and JSON), `rrbc plan` (JSON), the app's session (the
Explore card and the Plan tab) on a scene and on a measurement file, and `rrbc scene new` — on flat, tilted and 3-D
fiducial sets; a point 100 mm off a flat set's plane is outside, and its distance is said."""

from __future__ import annotations

import dataclasses
import json
import shutil

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rrbc_core.analysis import planning
from rrbc_core.cli import main
from rrbc_core.correction.pipeline import correct_measurements
from rrbc_core.interpolation.hull import assess_coverage
from rrbc_core.io.measurements import MeasurementSet, read_measurements
from rrbc_core.io.measurements_write import write_measurements
from rrbc_core.io.scene import NamedPoints, Region, Target
from rrbc_core.io.scene_toml import load_scene
from rrbc_core.models.errormodels import ErrorModel
from rrbc_core.models.errorterms import IsotropicNoise
from rrbc_core.session import edits, planning_view
from rrbc_core.session.evaluation import Settings
from rrbc_core.session.explorer import ExplorerSession
from rrbc_viz.planning_panel import render_coverage
from rrbc_viz.selection_card import info_card
from tests.paths import DEMO

CENTRE = np.array([475.0, 0.0, 60.0])


def _fiducials(kind: str) -> tuple[np.ndarray, np.ndarray]:
    """(fiducials (16, 3), unit normal of their plane or None-like zeros for a volume), robot frame, mm."""
    x, y = np.meshgrid(np.linspace(-125.0, 125.0, 4), np.linspace(-200.0, 200.0, 4))
    grid = np.c_[x.ravel(), y.ravel(), np.zeros(16)]
    if kind == "flat":
        return CENTRE + grid, np.array([0.0, 0.0, 1.0])
    if kind == "tilted":
        rot = Rotation.from_euler("xy", [30.0, -20.0], degrees=True)
        return CENTRE + rot.apply(grid), rot.apply([0.0, 0.0, 1.0])
    two = np.vstack([grid[::2] + [0, 0, -60.0], grid[1::2] + [0, 0, 90.0]])
    return CENTRE + two, np.zeros(3)


def _queries(kind: str) -> tuple[np.ndarray, list[bool]]:
    fids, normal = _fiducials(kind)
    c = fids.mean(axis=0)
    if kind == "3d":
        q = [c, c + [0, 0, 40.0], c + [0, 0, 200.0], c + [400.0, 0, 0], c + [60.0, 80.0, -30.0]]
        return np.array(q), [True, True, False, False, True]
    inplane = fids[5] - fids[0]  # along the plate
    q = [c, c + 100.0 * normal, c + 3.0 * inplane, c + 0.5 * normal, fids[0] + 0.3 * inplane + 20.0 * normal]
    return np.array(q), [True, False, False, True, False]


def _scene(kind: str):
    fids, _ = _fiducials(kind)
    q, _ = _queries(kind)
    demo = load_scene(DEMO)
    targets = tuple(Target(f"Q{i}", p, Region("box", p, np.full(3, 4.0)), demo.tool_yaw_deg) for i, p in enumerate(q))
    noise = ErrorModel(robot=(IsotropicNoise(0.02),), sensor=(IsotropicNoise(0.02),))
    return dataclasses.replace(
        demo,
        fiducials=NamedPoints(tuple(f"P{i}" for i in range(len(fids))), fids),
        targets=targets,
        error_model=noise,
        error_model_table={"robot": [{"type": "isotropic_noise", "sigma_mm": 0.02}], "sensor": []},
    )


def _file(kind: str, path) -> MeasurementSet:
    """A measurement file of the same points read by a sensor at the demo's pose, without noise."""
    scene = _scene(kind)
    T = scene.sensor_to_robot
    reg = scene.registration.positions
    fids = scene.fiducials.positions
    q = scene.target_positions
    robot = np.vstack([reg, fids, q])
    n_r, n_f = len(reg), len(fids)
    roles = ["registration"] * n_r + ["fiducial"] * n_f + ["target"] * len(q)
    ids = list(scene.registration.ids) + list(scene.fiducials.ids) + [t.id for t in scene.targets]
    m = MeasurementSet(ids, roles, T.apply_inverse(robot), robot, np.full(len(ids), np.nan), [0] * len(ids))
    write_measurements(path, m)
    return read_measurements(path)


@pytest.mark.parametrize("kind", ["flat", "tilted", "3d"])
def test_every_caller_gives_the_same_verdict(kind, tmp_path, capsys):
    fids, _ = _fiducials(kind)
    q, expected = _queries(kind)
    ids = [f"Q{i}" for i in range(len(q))]
    core = assess_coverage(fids, q)
    assert core.inside.tolist() == expected

    # rrbc correct: the library, its JSON and its text
    mset = _file(kind, tmp_path / "data.csv")
    res = correct_measurements(mset)
    assert res.targets_coverage.inside.tolist() == expected
    assert (~res.targets_corrected.extrapolated).tolist() == expected
    assert main(["correct", str(tmp_path / "data.csv"), "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    assert [not t["extrapolated"] for t in js["targets"]] == expected
    assert main(["correct", str(tmp_path / "data.csv")]) == 0
    text = capsys.readouterr().out
    if kind != "3d":  # the point 100 mm off the plane: outside, and how far is said
        row = next(line for line in text.splitlines() if line.strip().startswith("Q1 "))
        assert "extrapolated: outside the fiducials' hull (100.0 mm off their plane)" in row
        assert js["targets"][1]["off_plane_mm"] == pytest.approx(100.0, abs=1e-6)

    # rrbc plan: the library and its JSON
    scene = _scene(kind)
    plan = planning.plan(scene, 0)
    assert plan.inside.tolist() == expected
    scene_path = tmp_path / "cell.toml"
    session = ExplorerSession.from_scene(scene, Settings(noise_scale=0.0))
    shutil.copy(scene.mesh_path, tmp_path / scene.mesh_path.name)  # a scene opens meshes in its own folder
    scene_path.write_text(edits.scene_toml(session))
    assert main(["plan", str(scene_path), "--json"]) == 0
    pj = json.loads(capsys.readouterr().out)
    assert [pj["inside_hull_per_target"][i] for i in ids] == expected

    # the app's session: the Explore card and the Plan tab, on the scene and on the measurement file
    ev = session.evaluate()
    assert ev.coverage.inside.tolist() == expected and (~ev.targets.extrapolated).tolist() == expected
    table = render_coverage(planning_view.planning_state(session), ev.coverage, ev.targets.ids)
    shown = [("| inside |" in line) for line in table.splitlines()[2:]]
    assert shown == expected
    for i, pid in enumerate(ids):
        card = info_card(ev, ("targets", pid))
        assert ("inside the fiducials' hull" in card) == expected[i]
    if kind != "3d":
        assert "outside the fiducials' hull (100.0 mm off their plane)" in info_card(ev, ("targets", "Q1"))
    measured = ExplorerSession.from_measurements(mset).evaluate()
    assert measured.coverage.inside.tolist() == expected
