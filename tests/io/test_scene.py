"""Tests for rrbc_core.io.scene: the shipped scenes, regions, the sensor pose, layouts, reach, and one-line errors for
malformed scene files."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from rrbc_core.errors import InputError
from rrbc_core.io.scene import Region, Scene, default_scene_path, sensor_pose
from rrbc_core.io.scene_toml import load_scene
from tests.paths import SCENES

SHIPPED = ("demo_workcell", "breadboard_vanwyk2018", "peg_in_hole_cell")

# UR5 (CB3) DH lengths, mm (docs/theory.md §5.1)
D1, A2, A3, D4, D5, D6 = 89.159, 425.0, 392.25, 109.15, 94.65, 82.3


@pytest.fixture(scope="module")
def scenes() -> dict[str, Scene]:
    return {name: load_scene(SCENES / f"{name}.toml") for name in SHIPPED}


# ------------------------------------------------------------------------------------------------------
# shipped scenes
# ------------------------------------------------------------------------------------------------------
def test_shipped_scenes_load(scenes):
    for name, s in scenes.items():
        assert s.path == (SCENES / f"{name}.toml").resolve()
        assert s.mesh_path.is_file() and s.mesh_path.stat().st_size < 1_000_000
        assert s.robot_model == "ur5"
        assert s.joint_seed.shape == (6,)
        assert len(s.registration) >= 3 and len(s.targets) >= 1
        assert s.error_model is not None and s.error_model_table
        mesh = s.load_mesh()
        assert len(mesh.faces) > 0 and mesh.metadata["parts"]
        names = {p[0] for p in mesh.metadata["parts"]}
        assert "robot_base" in names
        assert mesh.metadata["parts"][-1][2] == len(mesh.faces)


def test_default_scene_is_the_demo():
    p = default_scene_path()
    assert p == (SCENES / "demo_workcell.toml").resolve()
    s = load_scene(p)
    assert s.name == "Demo work cell"


def test_demo_scene_facts(scenes):
    s = scenes["demo_workcell"]
    assert 8 <= len(s.fiducials) <= 12
    assert 6 <= len(s.targets) <= 8
    assert len(s.registration) == 6
    assert len(s.candidates) == 8 * 11 * 3
    # fiducials are not coplanar
    f = s.fiducials.positions - s.fiducials.positions.mean(0)
    assert np.linalg.svd(f, compute_uv=False)[-1] > 10.0
    # targets 350-600 mm from the base, the sensor 1.2-1.5 m up and looking down at the plate
    rho = np.hypot(*s.target_positions[:, :2].T)
    assert rho.min() > 350 and rho.max() < 600
    assert 1200 <= s.sensor_position[2] <= 1500
    assert s.sensor_to_robot.rotation[2, 2] < -0.5  # sensor +z points downwards
    # bias model present and noise small: kinematic error term + noise of a few hundredths of a mm
    assert "kinematic" in s.error_model.kinds
    assert s.error_model_table["robot"][1]["sigma_mm"] == 0.03
    assert s.error_model_table["sensor"][0] == {
        "type": "anisotropic_noise",
        "sigma_perp_mm": 0.02,
        "sigma_along_mm": 0.06,
    }
    assert s.line_of_sight


def test_fiducial_hull_contains_every_target_region(scenes):
    from scipy.spatial import Delaunay

    for name in ("demo_workcell", "peg_in_hole_cell"):
        s = scenes[name]
        tri = Delaunay(s.fiducials.positions)
        for t in s.targets:
            lo, hi = t.region.bounds()
            corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
            assert np.all(tri.find_simplex(corners) >= 0), f"{name}: {t.id} region leaves the fiducial hull"


def test_regions_contain_their_targets_and_samples_stay_inside(scenes):
    rng = np.random.default_rng(0)
    for s in scenes.values():
        for t in s.targets:
            assert t.region.contains(t.position)
            np.testing.assert_array_equal(t.region.center, t.position)
            pts = t.region.sample(rng, 500)
            assert pts.shape == (500, 3)
            assert np.all(t.region.contains(pts))
            lo, hi = t.region.bounds()
            assert np.all(pts >= lo - 1e-9) and np.all(pts <= hi + 1e-9)
        ids, pts = s.sample_check_points()
        assert len(ids) == len(pts) == s.check_points_per_target * len(s.targets)


@pytest.mark.parametrize(
    "kind, size, volume",
    [
        ("box", [4.0, 2.0, 1.0], 8.0),
        ("sphere", [2.5, 2.5, 2.5], 4.0 / 3.0 * math.pi * 2.5**3),
        ("ellipsoid", [3.0, 2.0, 1.0], 4.0 / 3.0 * math.pi * 6.0),
    ],
)
def test_region_volume_matches_monte_carlo(kind, size, volume):
    region = Region(kind, [10.0, -20.0, 5.0], size)
    assert region.volume() == pytest.approx(volume, rel=1e-12)
    lo, hi = region.bounds()
    box_volume = float(np.prod(hi - lo))
    rng = np.random.default_rng(42)
    n = 200_000
    pts = lo + rng.random((n, 3)) * (hi - lo)
    frac = region.contains(pts, tol_mm=0.0).mean()
    p = volume / box_volume
    sigma = math.sqrt(p * (1 - p) / n) if p < 1 else 1.0 / n
    assert abs(frac - p) < 5 * sigma + 1e-12, (frac, p, sigma)
    # uniformity of sample(): the fraction of samples in the inner half-scale copy is 1/8
    s = region.sample(rng, 40_000)
    inner = Region(kind, region.center, region.size / 2)
    q = inner.contains(s, tol_mm=0.0).mean()
    assert abs(q - 0.125) < 5 * math.sqrt(0.125 * 0.875 / 40_000)


def test_region_rejects_bad_sizes():
    with pytest.raises(InputError):
        Region("box", [0, 0, 0], [1, -1, 1])
    with pytest.raises(InputError):
        Region("cube", [0, 0, 0], [1, 1, 1])


def test_sensor_pose_convention(scenes):
    for s in scenes.values():
        t = s.sensor_to_robot
        r = t.rotation
        np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
        assert np.linalg.det(r) == pytest.approx(1.0)
        # the sensor origin maps to `position`, +z towards look_at
        np.testing.assert_allclose(t.apply([0.0, 0.0, 0.0]), s.sensor_position)
        view = s.sensor_look_at - s.sensor_position
        dist = np.linalg.norm(view)
        np.testing.assert_allclose(t.apply([0.0, 0.0, dist]), s.sensor_look_at, atol=1e-9)
        np.testing.assert_allclose(t.apply_inverse(s.sensor_look_at), [0.0, 0.0, dist], atol=1e-9)
    # camera convention: x right, y down, z forward; horizontal look along +x with up = +z
    p = sensor_pose([0, 0, 0], [1, 0, 0], [0, 0, 1])
    np.testing.assert_allclose(p.rotation[:, 2], [1, 0, 0], atol=1e-12)  # z forward
    np.testing.assert_allclose(p.rotation[:, 1], [0, 0, -1], atol=1e-12)  # y down
    np.testing.assert_allclose(p.rotation[:, 0], [0, -1, 0], atol=1e-12)  # x right (looking along +x)


def test_breadboard_frame_N_and_layouts(scenes):
    s = scenes["breadboard_vanwyk2018"]
    assert s.sensor_kind == "ground_truth" and not s.line_of_sight
    # sensor frame = frame N: N x along the plate's 900 mm side (robot -y), N y = robot x, N z = up
    np.testing.assert_allclose(s.sensor_to_robot.rotation, [[0, 1, 0], [-1, 0, 0], [0, 0, 1]], atol=1e-12)
    n = s.sensor_to_robot.apply_inverse(s.sites.positions)
    assert len(s.sites) == 16
    np.testing.assert_allclose(n[:, 2], 11.0)
    np.testing.assert_allclose(n[:, :2] % 25.0, 0.0, atol=1e-9)  # on the 25 mm hole grid
    assert np.ptp(n[:, 0]) == pytest.approx(750.0) and np.ptp(n[:, 1]) == pytest.approx(525.0)
    assert n[:, 0].min() >= 0 and n[:, 0].max() <= 875 and n[:, 1].min() >= 0 and n[:, 1].max() <= 575
    assert s.fiducials.ids == s.sites.ids
    assert s.target_ids == tuple(f"T{k}" for k in range(1, 17))
    np.testing.assert_array_equal(s.target_positions, s.sites.positions)

    def span(layout):
        p = s.sensor_to_robot.apply_inverse(s.with_layout(layout).registration.positions)
        return np.ptp(p[:, 0]), np.ptp(p[:, 1])

    assert set(s.layouts) == {"small_3pt", "large_3pt", "large_5pt", "clustering"}
    assert span("small_3pt") == pytest.approx((250.0, 175.0))
    assert span("large_3pt") == pytest.approx((750.0, 525.0))
    assert span("large_5pt") == pytest.approx((750.0, 525.0))
    assert span("clustering") == pytest.approx((750.0, 525.0))
    five = s.with_layout("large_5pt")
    assert five.layout == "large_5pt" and len(five.registration) == 5
    assert five.fiducials.ids == s.fiducials.ids  # the layout leaves fiducials alone
    assert len(s.with_layout("large_3pt").registration) == 3
    assert len(s.with_layout("clustering").registration) == 4
    # the 5th point: inside the rectangle, off-centre, not collinear with any two corners
    corners = s.with_layout("clustering").registration.positions
    p5 = five.registration.position("P5")
    lo, hi = corners.min(0), corners.max(0)
    assert np.all(p5[:2] > lo[:2]) and np.all(p5[:2] < hi[:2])
    assert np.linalg.norm(p5[:2] - (lo[:2] + hi[:2]) / 2) > 50
    for i in range(4):
        for j in range(i + 1, 4):
            a, b = corners[i], corners[j]
            d = np.linalg.norm(np.cross(b - a, p5 - a)) / np.linalg.norm(b - a)
            assert d > 50, (i, j, d)
    with pytest.raises(InputError, match="no such layout"):
        s.with_layout("nope")


def test_demo_layouts(scenes):
    s = scenes["demo_workcell"]
    a = s.with_layout("plate_corners")
    assert len(a.fiducials) == 8 and a.registration is s.registration
    b = s.with_layout("minimal_registration")
    assert b.registration.ids == ("R1", "R2", "R4")


def _ur5_reach(points, tool_mm):
    """Plain geometric reach bound for a UR5 with the tool pointing down: (TCP distance from the shoulder,
    wrist-centre distance from the shoulder in the arm plane, horizontal distance from the base axis)."""
    p = np.atleast_2d(points)
    rho = np.hypot(p[:, 0], p[:, 1])
    in_plane = np.sqrt(np.maximum(rho**2 - D4**2, 0.0))  # the arm plane is offset by d4 from the base axis
    wrist_height = p[:, 2] + tool_mm + D6 + D5 - D1  # wrist-1 centre above the shoulder, tool pointing down
    return np.linalg.norm(p - [0.0, 0.0, D1], axis=1), np.hypot(in_plane, wrist_height), rho


def test_all_points_within_ur5_reach(scenes):
    for name, s in scenes.items():
        for kind, (ids, pts) in s.points_by_kind().items():
            if not len(ids):
                continue
            tcp, wrist, rho = _ur5_reach(pts, s.tool_mm)
            bad = [i for i, a, b, c in zip(ids, tcp, wrist, rho) if a > 800 or b > A2 + A3 - 10 or c < 150]
            assert not bad, f"{name} {kind}: out of UR5 reach: {bad}"


def test_points_are_on_surfaces_or_in_free_space(scenes):
    """Fiducials and targets lie on the mesh surface (breadboard: the seated stylus tip, 11 mm above the plate);
    nothing is buried inside a solid part."""
    import trimesh

    from rrbc_core.models.visibility import inside_solids

    for name, s in scenes.items():
        mesh = s.load_mesh()
        for kind in ("fiducials", "targets"):
            _, pts = s.points_by_kind()[kind]
            _, d, _ = trimesh.proximity.closest_point(mesh, pts)
            if name == "breadboard_vanwyk2018":
                np.testing.assert_allclose(d, 11.0 - 0.1, atol=1e-5)  # above the site-marker rings (top 0.1 mm)
            else:
                assert d.max() < 0.2, (name, kind, d.max())
        for kind, (ids, pts) in s.points_by_kind().items():
            if len(ids):
                inside = inside_solids(mesh, pts + [0.0, 0.0, 0.5])  # 0.5 mm above: off any surface
                assert not inside.any(), (name, kind, [i for i, x in zip(ids, inside) if x])


def test_site_reference_and_same_id_rules(tmp_path):
    path = _write(
        tmp_path,
        MINIMAL.replace(
            '[[fiducial]]\nid = "F1"\nposition = [400.0, 0.0, 0.0]',
            '[[site]]\nid = "S1"\nposition = [400.0, 0.0, 0.0]\n\n[[fiducial]]\nid = "S1"\n\n'
            '[[fiducial]]\nid = "R1"\nposition = [300.0, -200.0, 50.0]',
        ),
    )
    s = load_scene(path)
    np.testing.assert_array_equal(s.fiducials.position("S1"), [400.0, 0.0, 0.0])
    t = load_scene(
        _write(
            tmp_path,
            path.read_text().replace('id = "T1"\nposition = [450.0, 50.0, 0.0]', 'id = "T1"\nsite = "S1"'),
            "t.toml",
        )
    )
    np.testing.assert_array_equal(t.target("T1").position, [400.0, 0.0, 0.0])
    np.testing.assert_array_equal(t.target("T1").region.center, [400.0, 0.0, 0.0])
    assert s.fiducials.ids == ("S1", "R1", "F2")  # R1 is also a registration point, same place: allowed


# ------------------------------------------------------------------------------------------------------
# malformed scene files
# ------------------------------------------------------------------------------------------------------
MINIMAL = """\
[scene]
name = "t"
units = "mm"
mesh = "m.stl"

[robot]
model = "ur5"
tool_mm = 100.0

[sensor]
kind = "stereo"
position = [1000.0, 0.0, 1000.0]
look_at = [400.0, 0.0, 0.0]

[[registration]]
id = "R1"
position = [300.0, -200.0, 50.0]

[[registration]]
id = "R2"
position = [300.0, 200.0, 50.0]

[[registration]]
id = "R3"
position = [600.0, 0.0, 150.0]

[[fiducial]]
id = "F1"
position = [400.0, 0.0, 0.0]

[[fiducial]]
id = "F2"
position = [500.0, 0.0, 0.0]

[[target]]
id = "T1"
position = [450.0, 50.0, 0.0]
region = { kind = "box", size = [4.0, 4.0, 2.0] }

[[error_model.sensor]]
type = "isotropic_noise"
sigma_mm = 0.02
"""


def _write(tmp_path: Path, text: str, name: str = "scene.toml") -> Path:
    import trimesh

    mesh = tmp_path / "m.stl"
    if not mesh.exists():
        trimesh.creation.box(extents=[100, 100, 10]).export(mesh)
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_minimal_scene_loads(tmp_path):
    s = load_scene(_write(tmp_path, MINIMAL))
    assert s.fiducials.ids == ("F1", "F2")
    assert s.check_points_per_target == 20 and s.measurement_interval_s == 5.0 and s.seed == 0
    np.testing.assert_allclose(np.degrees(s.joint_seed), [0, -90, 90, -90, -90, 0])
    assert s.layouts == {} and len(s.candidates) == 0 and len(s.sites) == 0


def _replace(old, new):
    def edit(text):
        assert old in text, old
        return text.replace(old, new, 1)

    return edit


BAD_CASES = [
    # id, edit of MINIMAL, key path expected in the message, fragment expected in the message
    ("syntax", _replace('name = "t"', 'name = "t'), "line 2", "TOML syntax error"),
    ("syntax-eq", _replace("units = ", "units "), "line 3", "TOML syntax error"),
    ("missing-mesh-key", _replace('mesh = "m.stl"\n', ""), "scene.mesh", "missing required key"),
    (
        "missing-sensor",
        _replace('[sensor]\nkind = "stereo"\nposition = [1000.0, 0.0, 1000.0]\nlook_at = [400.0, 0.0, 0.0]\n', ""),
        "sensor",
        "missing required key",
    ),
    (
        "missing-targets",
        lambda t: t.split("[[target]]")[0] + t.split("size = [4.0, 4.0, 2.0] }\n")[1],
        "target",
        "missing required key",
    ),
    ("missing-id", _replace('id = "F2"\n', ""), "fiducial[1].id", "missing required key"),
    (
        "unknown-key",
        _replace("look_at =", "looc_at ="),
        "sensor.looc_at",
        "valid keys in [sensor]: kind, position, look_at, up",
    ),
    ("unknown-top", _replace("[[fiducial]]", "[[fiducials]]"), "fiducials", "unknown key"),
    ("unknown-point-key", _replace('id = "F1"', 'id = "F1"\npos = [1, 2, 3]'), "fiducial[0].pos", "unknown key"),
    (
        "not-a-number",
        _replace("[300.0, 200.0, 50.0]", '[300.0, "a", 50.0]'),
        "registration[1].position",
        "must be 3 finite numbers",
    ),
    (
        "non-finite",
        _replace("[300.0, 200.0, 50.0]", "[300.0, inf, 50.0]"),
        "registration[1].position",
        "got [300.0, inf, 50.0]",
    ),
    (
        "nan",
        _replace("[300.0, 200.0, 50.0]", "[300.0, nan, 50.0]"),
        "registration[1].position",
        "must be 3 finite numbers",
    ),
    (
        "wrong-length",
        _replace("[300.0, 200.0, 50.0]", "[300.0, 200.0]"),
        "registration[1].position",
        "must be 3 finite numbers",
    ),
    ("units", _replace('units = "mm"', 'units = "m"'), "scene.units", 'only "mm"'),
    ("mesh-missing", _replace('"m.stl"', '"meshes/none.glb"'), "scene.mesh", "mesh file not found"),
    ("mesh-unloadable", _replace('"m.stl"', '"garbage.glb"'), "scene.mesh", "cannot load"),
    (
        "region-kind",
        _replace('kind = "box"', 'kind = "cube"'),
        "target[0].region.kind",
        "valid kinds: box, sphere, ellipsoid",
    ),
    (
        "region-size",
        _replace("size = [4.0, 4.0, 2.0]", "size = [10, -5, 3]"),
        "target[0].region.size",
        "must be 3 positive numbers, got [10, -5, 3]",
    ),
    (
        "region-zero",
        _replace('{ kind = "box", size = [4.0, 4.0, 2.0] }', '{ kind = "sphere", radius = 0 }'),
        "target[0].region.radius",
        "positive",
    ),
    (
        "region-key",
        _replace('{ kind = "box", size = [4.0, 4.0, 2.0] }', '{ kind = "box", radius = 2 }'),
        "target[0].region.radius",
        "unknown key",
    ),
    (
        "region-missing",
        _replace('region = { kind = "box", size = [4.0, 4.0, 2.0] }', ""),
        "target[0].region",
        "missing required key",
    ),
    ("duplicate-id", _replace('id = "F2"', 'id = "F1"'), "fiducial[1].id", "duplicate id 'F1' (also fiducial[0])"),
    ("same-id-elsewhere", _replace('id = "F2"', 'id = "R1"'), "fiducial[1].position", "one id names one place"),
    (
        "position-omitted",
        _replace('id = "F2"\nposition = [500.0, 0.0, 0.0]', 'id = "F2"'),
        "fiducial[1].position",
        "missing required key",
    ),
    (
        "look-at-equal",
        _replace("look_at = [400.0, 0.0, 0.0]", "look_at = [1000.0, 0.0, 1000.0]"),
        "sensor.look_at",
        "equals sensor.position",
    ),
    (
        "up-parallel",
        _replace("look_at = [400.0, 0.0, 0.0]", "look_at = [1000.0, 0.0, 0.0]\nup = [0, 0, 1]"),
        "sensor.up",
        "parallel",
    ),
    (
        "up-default-parallel",
        _replace("look_at = [400.0, 0.0, 0.0]", "look_at = [1000.0, 0.0, 0.0]"),
        "sensor.up",
        "(the default) is parallel",
    ),
    ("robot-model", _replace('model = "ur5"', 'model = "kuka"'), "robot.model", "must be one of 'ur5'"),
    ("tool-negative", _replace("tool_mm = 100.0", "tool_mm = -1"), "robot.tool_mm", ">= 0"),
    (
        "joint-seed",
        _replace("tool_mm = 100.0", "tool_mm = 100.0\njoint_seed_deg = [0, 0, 0, 0, 0]"),
        "robot.joint_seed_deg",
        "6 finite numbers",
    ),
    ("sensor-kind", _replace('kind = "stereo"', 'kind = "lidar"'), "sensor.kind", "must be one of"),
    ("seed", _replace('units = "mm"', 'units = "mm"\nseed = -1'), "scene.seed", "integer >= 0"),
    (
        "too-few-registration",
        lambda t: t.replace('[[registration]]\nid = "R3"\nposition = [600.0, 0.0, 150.0]\n', ""),
        "registration",
        "at least 3",
    ),
    ("collinear-registration", _replace("[600.0, 0.0, 150.0]", "[300.0, 0.0, 50.0]"), "registration", "collinear"),
    ("target-as-table", lambda t: t.replace("[[target]]", "[target]"), "target", "array of tables"),
    (
        "check-points",
        lambda t: t + "\n[simulation]\ncheck_points_per_target = 2.5\n",
        "simulation.check_points_per_target",
        "integer",
    ),
    (
        "interval",
        lambda t: t + "\n[simulation]\nmeasurement_interval_s = -5\n",
        "simulation.measurement_interval_s",
        ">= 0",
    ),
    (
        "layout-unknown-id",
        lambda t: t + '\n[layouts.L]\nregistration = ["R1", "R9", "R3"]\n',
        "layouts.L.registration[1]",
        "unknown id 'R9'",
    ),
    ("layout-empty", lambda t: t + '\n[layouts.L]\ndescription = "x"\n', "layouts.L", "needs a registration list"),
    ("layout-key", lambda t: t + '\n[layouts.L]\nfiducial = ["F1"]\n', "layouts.L.fiducial", "unknown key"),
    (
        "grid-too-big",
        lambda t: t + "\n[candidates]\ngrid = { min = [0, 0, 0], max = [1000, 1000, 1000], step = [1, 1, 1] }\n",
        "candidates.grid.step",
        "limit",
    ),
    (
        "grid-order",
        lambda t: t + "\n[candidates]\ngrid = { min = [0, 0, 0], max = [10, -10, 10], step = [1, 1, 1] }\n",
        "candidates.grid.max",
        ">= candidates.grid.min",
    ),
    ("target-id-is-fiducial", _replace('id = "T1"', 'id = "F1"'), "target[0].id", "a target needs an id of its own"),
    (
        "site-unknown",
        lambda t: t.replace('id = "T1"\nposition = [450.0, 50.0, 0.0]', 'id = "T1"\nsite = "S9"'),
        "target[0].site",
        "unknown site 'S9'",
    ),
    ("site-and-position", _replace('id = "T1"', 'id = "T1"\nsite = "S9"'), "target[0].site", "not both"),
    ("error-model-value", _replace("sigma_mm = 0.02", "sigma_mm = -0.02"), "error_model.sensor[0]", "sigma_mm"),
    (
        "error-model-type",
        _replace('type = "isotropic_noise"', 'type = "isotropic"'),
        "error_model.sensor[0]",
        "unknown type",
    ),
    ("error-model-key", _replace("sigma_mm = 0.02", "sigma = 0.02"), "error_model.sensor[0]", "unknown key 'sigma'"),
    (
        "error-model-side",
        _replace('type = "isotropic_noise"\nsigma_mm = 0.02', 'type = "kinematic"\nseed = 1'),
        "error_model.sensor[0]",
        "robot-side",
    ),
]


@pytest.mark.parametrize("edit, key, fragment", [c[1:] for c in BAD_CASES], ids=[c[0] for c in BAD_CASES])
def test_malformed_scene_gives_one_line_error(tmp_path, edit, key, fragment):
    (tmp_path / "garbage.glb").write_bytes(b"this is not a mesh")
    path = _write(tmp_path, edit(MINIMAL))
    with pytest.raises(InputError) as info:
        load_scene(path)
    msg = str(info.value)
    assert "\n" not in msg and "\r" not in msg, msg
    assert msg.startswith(f"{path}: "), msg
    assert f": {key}" in msg, msg
    assert fragment in msg, msg


def test_missing_and_undecodable_files(tmp_path):
    missing = tmp_path / "nope.toml"
    with pytest.raises(InputError) as info:
        load_scene(missing)
    assert str(info.value).startswith(f"{missing}: ") and "cannot read" in str(info.value)
    bad = tmp_path / "latin1.toml"
    bad.write_bytes(MINIMAL.replace('name = "t"', 'name = "caf\xe9"').encode("latin-1"))
    with pytest.raises(InputError) as info:
        load_scene(bad)
    assert str(info.value).startswith(f"{bad}: line 2") and "UTF-8" in str(info.value)


def test_default_scene_path_missing(monkeypatch, tmp_path):
    import rrbc_core.io.scene as scene_mod

    monkeypatch.setattr(scene_mod, "__file__", str(tmp_path / "pkg" / "scene.py"))
    with pytest.raises(InputError, match="default scene is missing"):
        default_scene_path()


def test_robot_models_ur10_and_none(tmp_path):
    """robot.model picks the arm of the scene's kinematic error terms (UR10's DH for "ur10"); "none" is a robot
    without kinematics and refuses a kinematic term."""
    from rrbc_core.models.kinematics import UR10

    text = (SCENES / "demo_workcell.toml").read_text(encoding="utf-8")
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "demo_workcell.glb").write_bytes((SCENES / "meshes" / "demo_workcell.glb").read_bytes())
    ur10 = tmp_path / "ur10.toml"
    ur10.write_text(text.replace('model = "ur5"', 'model = "ur10"'), encoding="utf-8")
    scene = load_scene(ur10)
    term = next(t for t in scene.error_model.terms("robot") if t.kind == "kinematic")
    assert term.dh.same_as(UR10.with_tool(scene.tool_mm))
    none = tmp_path / "none.toml"
    none.write_text(text.replace('model = "ur5"', 'model = "none"'), encoding="utf-8")
    with pytest.raises(InputError, match="kinematic error term needs an arm model"):
        load_scene(none)


# ------------------------------------------------------------------- the mesh stays in the scene's folder (issue 16)
@pytest.mark.parametrize("mesh", ["../m.stl", "/etc/passwd", "sub/../../m.stl", "link.stl"])
def test_a_mesh_outside_the_scenes_folder_is_refused_before_it_is_read(tmp_path, mesh):
    import os

    import trimesh

    outside = tmp_path / "m.stl"
    trimesh.creation.box(extents=[100, 100, 10]).export(outside)
    folder = tmp_path / "scene"
    folder.mkdir()
    os.symlink(outside, folder / "link.stl")  # a link inside that points out
    path = folder / "scene.toml"
    path.write_text(MINIMAL.replace('mesh = "m.stl"', f'mesh = "{mesh}"'), encoding="utf-8")
    with pytest.raises(InputError, match="leaves the scene's folder"):
        load_scene(path)


def test_a_mesh_symlink_loop_is_one_clear_error(tmp_path):
    import os

    os.symlink(tmp_path / "loop.stl", tmp_path / "loop.stl")
    path = tmp_path / "scene.toml"
    path.write_text(MINIMAL.replace('mesh = "m.stl"', 'mesh = "loop.stl"'), encoding="utf-8")
    with pytest.raises(InputError, match="scene.mesh"):
        load_scene(path)


def test_a_mesh_in_a_folder_below_the_scene_loads(tmp_path):
    import trimesh

    (tmp_path / "meshes").mkdir()
    trimesh.creation.box(extents=[100, 100, 10]).export(tmp_path / "meshes" / "m.stl")
    path = tmp_path / "scene.toml"
    path.write_text(MINIMAL.replace('mesh = "m.stl"', 'mesh = "meshes/m.stl"'), encoding="utf-8")
    assert load_scene(path).mesh_path == (tmp_path / "meshes" / "m.stl").resolve()


def test_a_byte_order_mark_is_accepted(tmp_path):
    path = _write(tmp_path, "\ufeff" + MINIMAL)
    assert load_scene(path).fiducials.ids == ("F1", "F2")


@pytest.mark.parametrize(
    "content, says",
    [("a = " + "[" * 5000 + "]" * 5000 + "\n", "nested too deeply"), (None, "not a regular file")],
)
def test_deep_nesting_and_special_files_are_one_clear_error(tmp_path, content, says):
    if content is None:
        import os

        path = tmp_path / "fifo.toml"
        os.mkfifo(path)  # reading it would block forever
    else:
        path = tmp_path / "deep.toml"
        path.write_text(content, encoding="utf-8")
    with pytest.raises(InputError, match=says):
        load_scene(path)


def test_an_unreachable_target_is_named_with_its_file_and_id(tmp_path):
    text = (SCENES / "demo_workcell.toml").read_text(encoding="utf-8")
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "demo_workcell.glb").write_bytes((SCENES / "meshes" / "demo_workcell.glb").read_bytes())
    path = tmp_path / "far.toml"
    path.write_text(text.replace("position = [400.0, -150.0, 15.0]", "position = [4000.0, -150.0, 15.0]", 1))
    with pytest.raises(InputError) as e:
        load_scene(path)
    msg = str(e.value)
    assert msg.startswith(str(path)) and "target[0].position" in msg and "H1" in msg and "reach" in msg
