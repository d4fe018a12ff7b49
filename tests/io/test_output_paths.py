"""`--out` and every file the project writes (issue 16): special files are never replaced, links are written
through, an empty or impossible path is refused at once (before a run), one line, exit 2."""

import os

import pytest

from rrbc_core.errors import InputError
from rrbc_core.io.measurements_write import atomic_write_text, output_path
from tests.paths import SCENES


def test_a_fifo_a_directory_and_an_empty_path_are_refused(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    for bad in (fifo, tmp_path, ""):
        with pytest.raises(InputError):
            atomic_write_text(bad, "x")
    assert fifo.is_fifo()  # still a FIFO, not replaced by a regular file


def test_a_character_device_is_never_replaced():
    with pytest.raises(InputError, match="not a regular file"):
        output_path("/dev/null")
    assert not os.path.isfile("/dev/null")


def test_a_symlink_is_written_through(tmp_path):
    target = tmp_path / "real.csv"
    target.write_text("old", encoding="utf-8")
    link = tmp_path / "link.csv"
    os.symlink(target, link)
    atomic_write_text(link, "new")
    assert link.is_symlink() and target.read_text(encoding="utf-8") == "new"


def test_simulate_refuses_a_bad_out_before_the_run(tmp_path, monkeypatch, capsys):
    import rrbc_core.simulation.montecarlo as mc
    from rrbc_core.cli import main

    def no_run(*a, **k):
        raise AssertionError("the simulation ran before --out was checked")

    monkeypatch.setattr(mc, "simulate", no_run)
    scene = str(SCENES / "demo_workcell.toml")
    assert main(["simulate", scene, "--out", str(tmp_path / "no" / "x.csv")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "no such folder" in err
    assert main(["simulate", scene, "--out", ""]) == 2 and "empty" in capsys.readouterr().err
    assert main(["simulate", scene, "--out", "/dev/null"]) == 2 and "not a regular file" in capsys.readouterr().err


def test_only_regular_files_are_read_and_up_to_the_stated_size(tmp_path, monkeypatch):
    import rrbc_core.io.measurements as meas

    with pytest.raises(InputError, match="not a regular file"):
        meas.read_measurements("/dev/zero")  # would read gigabytes
    big = tmp_path / "big.csv"
    big.write_bytes(b"id,role\n" + b"x" * 2000)
    monkeypatch.setattr(meas, "FILE_LIMIT_BYTES", 1000)
    with pytest.raises(InputError, match="larger than"):
        meas.read_measurements(big)


def test_super_linear_work_has_stated_limits():
    import numpy as np

    from rrbc_core.interpolation.gp import GP, MAX_FIDUCIALS

    pts = np.random.default_rng(0).uniform(0, 1000, (MAX_FIDUCIALS + 1, 3))
    with pytest.raises(InputError, match=f"at most {MAX_FIDUCIALS} fiducials"):
        GP().fit(pts, np.zeros_like(pts))


def test_tps_linear_and_the_hull_test_have_stated_limits(monkeypatch):
    import numpy as np

    from rrbc_core.interpolation import hull, linear, tps
    from rrbc_core.interpolation.hull import hull_flags

    pts = np.random.default_rng(0).uniform(0, 1000, (tps.MAX_FIDUCIALS + 1, 3))
    with pytest.raises(InputError, match="tps interpolates at most 5000 fiducials"):
        tps.TPS().fit(pts, np.zeros_like(pts))
    monkeypatch.setattr(linear, "MAX_FIDUCIALS", 100)  # the check comes before the triangulation: no 200 001 needed
    with pytest.raises(InputError, match="linear interpolates at most 100 fiducials"):
        linear.Linear().fit(pts[:101], np.zeros((101, 3)))
    sphere = np.random.default_rng(1).normal(size=(400, 3))
    sphere *= 100 / np.linalg.norm(sphere, axis=1)[:, None]  # every point on the hull: ~800 facets
    query = np.zeros((2000, 3))
    assert not hull_flags(sphere, query)[0].any()
    monkeypatch.setattr(hull, "HULL_WORK_LIMIT", 100_000)
    with pytest.raises(InputError, match="would check 2,000 points against the .* facets"):
        hull_flags(sphere, query)


def test_check_points_per_target_is_bounded(tmp_path):
    from rrbc_core.io.scene_toml import MAX_CHECK_POINTS_PER_TARGET, load_scene

    text = (SCENES / "demo_workcell.toml").read_text(encoding="utf-8")
    text = text.replace("check_points_per_target = 20", "check_points_per_target = 1000000000")
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "demo_workcell.glb").write_bytes((SCENES / "meshes" / "demo_workcell.glb").read_bytes())
    path = tmp_path / "s.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(InputError, match=f"at most {MAX_CHECK_POINTS_PER_TARGET}"):
        load_scene(path)


def test_diagnose_states_its_limit(monkeypatch):
    import numpy as np

    import rrbc_core.analysis.diagnosis_stats as ds
    from rrbc_core.analysis.diagnosis import diagnose
    from rrbc_core.io.measurements import MeasurementSet

    monkeypatch.setattr(ds, "MAX_POINTS", 10)
    n = 11
    p = np.random.default_rng(0).uniform(0, 100, (n, 3))
    m = MeasurementSet(tuple(f"P{i}" for i in range(n)), ("both",) * n, p, p, np.zeros(n), (0,) * n)
    with pytest.raises(InputError, match="at most 10 distinct points"):
        diagnose(m)


def test_simulate_states_its_trials_limit():
    from rrbc_core.io.scene import default_scene_path
    from rrbc_core.io.scene_toml import load_scene
    from rrbc_core.simulation.montecarlo import MAX_TRIALS, simulate

    with pytest.raises(InputError, match="trials must be 1 to"):
        simulate(load_scene(default_scene_path()), MAX_TRIALS + 1)


def test_simulate_icp_and_plan_add_state_their_limits():
    """Issue 42, item 4: `simulate --icp` and `plan --add` are bounded with a refusal in one line, before any work."""
    import time

    from rrbc_core.analysis.planning import MAX_ADD
    from rrbc_core.io.scene import default_scene_path
    from rrbc_core.simulation.montecarlo import MAX_ICP_TRIALS
    from tests.support.cli_run import rrbc

    scene = default_scene_path()
    t0 = time.perf_counter()
    for args, said in (
        (["simulate", scene, "--trials", "2", "--icp", str(MAX_ICP_TRIALS + 1)], "--icp must be 0 to"),
        (["simulate", scene, "--trials", "2", "--icp", "1000000000"], "--icp must be 0 to"),
        (["plan", scene, "--add", str(MAX_ADD + 1)], f"at most {MAX_ADD} fiducials"),
    ):
        r = rrbc(*args)
        assert r.returncode == 2 and r.stdout == "", (args, r.stdout)
        assert len(r.stderr.strip().splitlines()) == 1 and said in r.stderr, r.stderr
    assert time.perf_counter() - t0 < 30  # refused before the work, not after it
