"""The stationing YAML reader (io.stationing_yaml) and `rrbc convert` on it: a file of our own in the public data
sets' form, made from our lift-column arm seen by an instrument at a known pose per station."""

import json

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from rrbc_core.cli import main
from rrbc_core.errors import InputError
from rrbc_core.io.groups import group_names
from rrbc_core.io.measurements import read_measurements
from rrbc_core.io.stationing_yaml import read_stationing_yaml
from rrbc_core.models.urdf import load_urdf
from rrbc_core.registration.strategies import least_squares
from tests.support.urdf_arms import LIFT_ARM, random_poses

CHAIN = load_urdf(LIFT_ARM, tip="tcp")


def _station_items(rng, n, start_id, rot, t, noise_mm):
    q = random_poses(CHAIN, rng, n)
    file_q = q / np.array([i.scale for i in CHAIN.inputs])  # URDF units: metres, radians
    p_robot = CHAIN.forward(q)
    p_instr = (p_robot - t) @ rot + rng.normal(0, noise_mm, p_robot.shape)  # robot = rot @ instr + t
    return [
        {
            "id": start_id + k,
            "time": 1.7e9 + start_id + k,
            "upside_down": False,
            "joint_states": [float(v) for v in file_q[k]],
            "prism_position": [float(v) for v in p_instr[k] / 1000.0],
        }
        for k in range(n)
    ], p_robot


def write_yaml(path, seed=0, noise_mm=0.0, empty_space=True):
    """A stationing file: 2 heights x 2 solution spaces with 8 stationing and 10 evaluation points each (and a
    third space with evaluation points only); returns the planted poses per station."""
    rng = np.random.default_rng(seed)
    heights, planted, next_id = {}, {}, 0
    for h in ("1.5", "2.5"):
        spaces = {}
        for s in (0, 7):
            rot = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
            t = rng.normal(0, 2000.0, 3)
            st, _ = _station_items(rng, 8, next_id, rot, t, noise_mm)
            ev, _ = _station_items(rng, 10, next_id + 8, rot, t, noise_mm)
            next_id += 18
            spaces[s] = {"stationing_measurements": st, "evaluation_measurements": ev}
            planted[f"h{h}_s{s}"] = (rot, t)
        if empty_space:
            ev, _ = _station_items(rng, 3, next_id, np.eye(3), np.zeros(3), noise_mm)
            next_id += 3
            spaces[4] = {"stationing_measurements": [], "evaluation_measurements": ev}
        heights[float(h)] = {"solution_spaces": spaces}
    path.write_text(yaml.safe_dump({"joint_names": list(CHAIN.columns), "column_heights": heights}))
    return planted


def test_stations_roles_and_frames(tmp_path):
    f = tmp_path / "site.yaml"
    planted = write_yaml(f, seed=3)
    mset = read_stationing_yaml(f, CHAIN)
    assert group_names(mset) == ("h1.5_s0", "h1.5_s7", "h2.5_s0", "h2.5_s7")  # the space without stationing is left out
    assert len(mset) == 4 * 18
    groups = np.array(mset.extra["group"])
    roles = np.array(mset.roles)
    assert set(roles[[i.startswith("S") for i in mset.ids]]) == {"both"}
    assert set(roles[[i.startswith("E") for i in mset.ids]]) == {"check"}
    q = np.array([[float(v) for v in mset.extra[c]] for c in CHAIN.columns]).T
    np.testing.assert_allclose(mset.robot, CHAIN.forward(q * [i.scale for i in CHAIN.inputs]), atol=1e-9)
    for g, (rot, t) in planted.items():  # each station's instrument pose is the one planted (noise-free file)
        m = groups == g
        reg = least_squares(mset.sensor[m], mset.robot[m])
        np.testing.assert_allclose(reg.mapping.rotation, rot, atol=1e-9)
        np.testing.assert_allclose(reg.mapping.translation, t, atol=1e-6)


@pytest.mark.parametrize("choice,parity", [("half", 0), ("half-swapped", 1)])
def test_half_of_the_evaluation_points_become_fiducials(tmp_path, choice, parity):
    f = tmp_path / "site.yaml"
    write_yaml(f)
    mset = read_stationing_yaml(f, CHAIN, fiducials=choice)
    groups = np.array(mset.extra["group"])
    for g in group_names(mset):
        ev = [r for r, i, gg in zip(mset.roles, mset.ids, groups) if gg == g and i.startswith("E")]
        assert ev == ["fiducial" if k % 2 == parity else "check" for k in range(10)]


def test_bad_files_are_refused_in_one_line(tmp_path):
    f = tmp_path / "site.yaml"
    write_yaml(f)
    data = yaml.safe_load(f.read_text())
    data["joint_names"] = data["joint_names"][:-1]  # not the chain's joints
    f.write_text(yaml.safe_dump(data))
    with pytest.raises(InputError, match="joint_names"):
        read_stationing_yaml(f, CHAIN)
    data["joint_names"] = list(CHAIN.columns)
    data["column_heights"][1.5]["solution_spaces"][0]["evaluation_measurements"][2]["prism_position"] = [1, "x", 2]
    f.write_text(yaml.safe_dump(data))
    with pytest.raises(InputError, match=r"station h1\.5_s0, evaluation measurement 3: 'prism_position'"):
        read_stationing_yaml(f, CHAIN)
    f.write_text("joint_names: [a]\n")
    with pytest.raises(InputError, match="not a stationing file"):
        read_stationing_yaml(f, CHAIN)
    f.write_text("a: [b\n")
    with pytest.raises(InputError, match="not a readable YAML file"):
        read_stationing_yaml(f, CHAIN)
    with pytest.raises(InputError, match="no such file"):
        read_stationing_yaml(tmp_path / "none.yaml", CHAIN)


def test_rrbc_convert_writes_a_file_rrbc_reads_by_station(tmp_path, capsys):
    f = tmp_path / "site.yaml"
    write_yaml(f, seed=5, noise_mm=0.05)
    out = tmp_path / "site.csv"
    assert (
        main(
            [
                "convert",
                str(f),
                "--to",
                "csv",
                "--urdf",
                str(LIFT_ARM),
                "--tip",
                "tcp",
                "--fiducials",
                "half",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    assert "4 stations" in capsys.readouterr().out
    mset = read_measurements(out)
    assert group_names(mset) == ("h1.5_s0", "h1.5_s7", "h2.5_s0", "h2.5_s7")
    assert set(CHAIN.columns) <= set(mset.extra)
    assert main(["correct", str(out), "--json"]) == 0  # every station registers on its own: FRE at the noise
    res = json.loads(capsys.readouterr().out)
    assert max(g["registration"]["fre_rms_mm"] for g in res["groups"]) < 0.2


def test_rrbc_convert_refusals(tmp_path, capsys):
    f = tmp_path / "site.yaml"
    write_yaml(f)
    out = tmp_path / "site.csv"
    assert main(["convert", str(f), "--to", "csv", "--out", str(out)]) == 2  # no URDF
    assert main(["convert", str(f), "--to", "csv", "--urdf", str(LIFT_ARM), "--out", str(out)]) == 2  # no prism
    err = capsys.readouterr().err
    assert "--urdf" in err and "no link named 'prism'" in err and not out.exists()
