"""Fiducial planning (issue 7): coverage, predicted RMST, usable candidates, the optimiser and `rrbc plan`.

Tolerances:
* Coverage is a fraction of `n` uniform samples: its standard error is at most 0.5/√n (binomial); checks against a
  known fraction allow 4 standard errors.
* Fast (first-order) vs Monte Carlo: both use the same region samples, so only the Monte Carlo noise and the
  first-order truncation separate them. Allowed: 4 Monte Carlo standard errors plus 2 % of the value — theory
  notes §2.3 measured the first-order TRE covariance within 1–2 % of Monte Carlo; the bias part of the fast
  prediction is exact, not linearised.
* Noise-only rigid prediction vs Fitzpatrick's formula (metrics.expected_tre_fitzpatrick): the two are the same
  first-order quantity computed two ways (closed form vs central differences of the batched least-squares fit
  with a 1e-3 mm step), so they agree to rounding; allowed 1e-6 relative.
* Optimiser vs random: see `test_optimiser_beats_random_placement_on_average`.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import trimesh

from rrbc_core.analysis import planning
from rrbc_core.cli import main
from rrbc_core.correction import metrics
from rrbc_core.errors import InputError
from rrbc_core.io.scene import Region
from rrbc_core.io.scene_toml import load_scene
from rrbc_core.models.errormodels import ErrorModel
from rrbc_core.models.errorterms import IsotropicNoise
from rrbc_core.models.visibility import visible_points
from rrbc_core.studies.planning_study import candidate_grid, seeded_scene
from tests.paths import ROOT

SCENES = ["demo_workcell", "breadboard_vanwyk2018", "peg_in_hole_cell"]
#: Fiducials of the demo scene that leave the targets at y = +50 and +150 outside the hull (H2 at y = −50
#: is only partly inside).
PARTIAL = ["F1", "F3", "F5", "F6", "F9", "F10"]


@pytest.fixture(scope="module")
def demo():
    return load_scene(ROOT / "scenes" / "demo_workcell.toml")


@pytest.fixture(scope="module")
def partial(demo):
    """The demo cell with 6 of its fiducials (regions stick out of their hull) and the 5 x 5 x 5 candidate grid."""
    return dataclasses.replace(demo, fiducials=demo.fiducials.subset(PARTIAL), candidates=candidate_grid())


# ------------------------------------------------------------------------------------------------------
# coverage
# ------------------------------------------------------------------------------------------------------
CUBE = np.array([[x, y, z] for x in (0, 100) for y in (0, 100) for z in (0, 100)], float)


def test_coverage_of_regions_inside_half_outside_and_outside_a_cube():
    regions = [
        Region("box", [50, 50, 50], [20, 20, 20]),  # inside
        Region("box", [100, 50, 50], [20, 20, 20]),  # half outside (x > 100)
        Region("sphere", [300, 50, 50], [10, 10, 10]),
    ]  # outside
    n = 2000
    c = planning.coverage(CUBE, regions, samples_per_region=n, seed=3)
    se = 0.5 / np.sqrt(n)
    assert c[0] == 1.0 and c[2] == 0.0
    assert abs(c[1] - 0.5) <= 4 * se


def test_coverage_with_coplanar_fiducials_uses_the_polygon_and_the_plane_tolerance():
    square = np.array([[0, 0, 0], [100, 0, 0], [0, 100, 0], [100, 100, 0]], float)
    on_plane = Region("box", [50, 50, 0], [10, 10, 2 * planning.OFF_PLANE_TOL_MM * 0.9])  # within the tolerance
    corner = Region("box", [100, 100, 0], [10, 10, 1.0])  # a quarter inside the polygon
    above = Region("box", [50, 50, 100], [10, 10, 1.0])  # inside the polygon's prism, 100 mm off the plane
    thick = Region("box", [50, 50, 0], [10, 10, 4 * planning.OFF_PLANE_TOL_MM])  # half of it within 1 mm
    n = 2000
    c = planning.coverage(square, [on_plane, corner, above, thick], samples_per_region=n, seed=1)
    se = 0.5 / np.sqrt(n)
    assert c[0] == 1.0 and c[2] == 0.0
    assert abs(c[1] - 0.25) <= 4 * se
    assert abs(c[3] - 0.5) <= 4 * se


def test_coverage_degenerate_and_bad_input():
    r = [Region("box", [0, 0, 0], [1, 1, 1])]
    assert planning.coverage(np.zeros((0, 3)), r).tolist() == [0.0]
    # two points: their hull is a segment; a region around it is inside only within 1 mm of the line (the same rule
    # as the extrapolation flag: `interpolation.hull`), here the part of a 1 mm cube on the segment's side
    two = planning.coverage(CUBE[:2], r, samples_per_region=4000, seed=2)[0]
    assert abs(two - 0.5) <= 4 * 0.5 / np.sqrt(4000)
    with pytest.raises(InputError, match="shape"):
        planning.coverage(np.zeros((4, 2)), r)
    with pytest.raises(InputError, match="samples_per_region"):
        planning.coverage(CUBE, r, samples_per_region=0)


# ------------------------------------------------------------------------------------------------------
# prediction
# ------------------------------------------------------------------------------------------------------
def _noise_only(scene, sigma_robot=0.03, sigma_sensor=0.02):
    model = ErrorModel(robot=(IsotropicNoise(sigma_robot),), sensor=(IsotropicNoise(sigma_sensor),))
    return dataclasses.replace(scene, error_model=model)


def test_noise_only_rigid_prediction_is_fitzpatricks_formula(demo):
    """Isotropic noise, no bias: the rigid RMST² is the mean over the region samples of Fitzpatrick's <TRE²>
    (registration points as the fiducials of the rigid fit, net FLE² = 3σ_s² + 3σ_b²) plus the target's own
    sensor noise 3σ_s²."""
    s_r, s_s = 0.03, 0.02
    scene = _noise_only(demo, s_r, s_s)
    n = 16
    _, checks = scene.sample_check_points(rng=5, n=n)
    fle = np.sqrt(3 * s_s**2 + 3 * s_r**2)
    tre = metrics.expected_tre_fitzpatrick(scene.registration.positions, checks, fle)
    expected = np.sqrt(np.mean(tre**2 + 3 * s_s**2))
    pred = planning.predict_rmst(scene, scene.fiducials.positions, seed=5, samples_per_target=n)
    assert pred.rigid_mm == pytest.approx(expected, rel=1e-6)
    assert pred.method == "first-order"


def _agree(fast, mc, attr):
    a, b, se = getattr(fast, f"{attr}_mm"), getattr(mc, f"{attr}_mm"), getattr(mc, f"{attr}_std_mm")
    assert abs(a - b) <= 4 * se + 0.02 * b, (attr, a, b, se)


@pytest.mark.parametrize("name", ["noise-only demo", *SCENES])
def test_fast_prediction_agrees_with_monte_carlo(demo, name):
    scene = _noise_only(demo) if name == "noise-only demo" else load_scene(ROOT / "scenes" / f"{name}.toml")
    fid = scene.fiducials.positions
    fast = planning.predict_rmst(scene, fid, seed=2)
    mc = planning.predict_rmst(scene, fid, seed=2, trials=2000)
    assert mc.method == "monte-carlo" and mc.rrbc_std_mm > 0
    _agree(fast, mc, "rigid")
    _agree(fast, mc, "rrbc")


def test_noise_only_rrbc_is_worse_than_rigid_and_bias_makes_it_better(demo):
    """Theory notes §0: RRBC carries fiducial noise, so without bias it loses; with the demo's bias it wins."""
    noise = planning.predict_rmst(_noise_only(demo), demo.fiducials.positions)
    biased = planning.predict_rmst(demo, demo.fiducials.positions)
    assert noise.rrbc_mm > noise.rigid_mm
    assert biased.rrbc_mm < biased.rigid_mm


def test_no_fiducials_means_rigid_only_and_fast_enough(demo):
    p = planning.predict_rmst(demo, np.zeros((0, 3)))
    assert p.rrbc_mm == p.rigid_mm
    import time

    planning.predict_rmst(demo, demo.fiducials.positions)  # warm-up
    times = []
    for _ in range(5):
        t0 = time.perf_counter()
        planning.predict_rmst(demo, demo.fiducials.positions)
        times.append(time.perf_counter() - t0)
    # the app's budget is ~30 ms per call (measured ~10 ms on the demo); best of 5 < 0.1 s leaves CI headroom
    assert min(times) < 0.1, times


def test_prediction_input_errors(demo):
    with pytest.raises(InputError, match="shape"):
        planning.predict_rmst(demo, np.zeros((3, 2)))
    with pytest.raises(InputError, match="coincide"):
        planning.predict_rmst(demo, np.array([[400.0, 0, 20], [400.0, 0, 20], [500, 0, 20]]))
    with pytest.raises(InputError, match="trials"):
        planning.predict_rmst(demo, demo.fiducials.positions, trials=-1)
    with pytest.raises(InputError, match="reach"):
        planning.predict_rmst(demo, np.array([[5000.0, 0, 0], [400, 0, 20], [500, 0, 20]]))


# ------------------------------------------------------------------------------------------------------
# the tests
# ------------------------------------------------------------------------------------------------------
def test_regions_sticking_out_of_the_hull_rmst_drops_and_no_rule_does_better(partial):
    """The objective is the predicted RMST (issue 25): with regions sticking out of the hull the suggestion lowers
    it significantly and no simple rule's set is predicted lower."""
    res = planning.plan(partial, 4)
    assert np.any(res.coverage < 1)
    assert res.coverage[list(res.target_ids).index("H4")] == 0.0
    assert res.predicted_after.rrbc_mm <= min(b.rrbc_mm for b in res.baselines.values())
    before, after = res.predicted, res.predicted_after
    assert after.rrbc_mm + 3 * np.hypot(after.rrbc_std_mm, before.rrbc_std_mm) < before.rrbc_mm
    assert len(res.suggested_ids) == 4 and res.suggested.shape == (4, 3)
    grid = candidate_grid()
    for pid, pos in zip(res.suggested_ids, res.suggested):
        assert np.allclose(grid.position(pid), pos)


STUDY_MEAN_GAIN = 0.310  # docs/planning.md (scripts/plan_confirm.py --out docs): 12 seeded scenes, seeds 0-11
STUDY_SD_GAIN = 0.104
TEST_SEEDS = (100, 101, 102, 103, 104, 105)


@pytest.mark.slow
def test_optimiser_beats_random_placement_on_average():
    """Measured margin (docs/planning.md, `scripts/plan_confirm.py --out docs`, seeds 0-11): over 12 seeded demo
    scenes (6 of the 12 fiducials kept, kinematic error redrawn, 5 x 5 x 5 candidate grid, K = 4) the optimiser's
    predicted RRBC RMST is 31.0 % below the mean of random placements (sd 10.4 % between scenes, min 10.6 %).
    Here, on 6 other seeds, the mean gain must reach the study's mean minus 3 standard errors of a 6-scene mean:
    0.310 − 3 × 0.104 / √6 = 18.3 %. Every scene must also gain something (the study's minimum was 10.6 %)."""
    from rrbc_core.studies.planning_study import optimiser_vs_random

    rows = optimiser_vs_random(TEST_SEEDS)
    gains = np.array([r["gain"] for r in rows])
    bound = STUDY_MEAN_GAIN - 3 * STUDY_SD_GAIN / np.sqrt(len(gains))
    assert gains.mean() >= bound, (gains, bound)
    assert np.all(gains > 0), gains


def test_seeded_scenes_differ():
    a, b = seeded_scene(1), seeded_scene(2)
    assert a.fiducials.ids != b.fiducials.ids or not np.allclose(a.fiducials.positions, b.fiducials.positions)


def _with_obstacles(scene, hide: np.ndarray, bury: np.ndarray):
    """The scene's mesh plus a small plate halfway between the sensor and each point of `hide` (so it is
    hidden) and a 30 x 30 x 20 mm block centred on each point of `bury` (so it is inside a solid)."""
    base = scene.load_mesh()
    parts = list(base.metadata["parts"])
    meshes = [base]
    nf = len(base.faces)
    s = scene.sensor_position
    for k, p in enumerate(hide):
        m = trimesh.creation.box(extents=[16, 16, 4], transform=trimesh.transformations.translation_matrix((p + s) / 2))
        meshes.append(m)
        parts.append((f"wall{k}", nf, nf + len(m.faces)))
        nf += len(m.faces)
    for k, p in enumerate(bury):
        m = trimesh.creation.box(extents=[30, 30, 20], transform=trimesh.transformations.translation_matrix(p))
        meshes.append(m)
        parts.append((f"block{k}", nf, nf + len(m.faces)))
        nf += len(m.faces)
    mesh = trimesh.util.concatenate(meshes)
    mesh.metadata["parts"] = parts
    return dataclasses.replace(scene, _mesh=mesh)


def test_occluded_and_buried_candidates_are_never_suggested(partial):
    """The optimiser's own first choices are hidden behind walls / buried in blocks; the new plan must avoid
    them (and everything else the ray cast rejects), and the clear scene shows that it would have taken them."""
    clear = planning.plan(partial, 4)
    grid = candidate_grid()
    first = [grid.position(i) for i in clear.suggested_ids]
    hide, bury = np.array(first[:2]), np.array(first[2:3])
    blocked = _with_obstacles(partial, hide, bury)
    mask, reasons = planning.usable_candidates(blocked)
    for pid in clear.suggested_ids[:2]:
        assert reasons[pid].startswith("hidden from the sensor by wall"), reasons.get(pid)
    assert reasons[clear.suggested_ids[2]] == "inside solid geometry (block0)"
    hidden = [i for i, r in reasons.items() if r.startswith("hidden")]
    assert not np.any(
        visible_points(blocked.load_mesh(), blocked.sensor_position, np.array([grid.position(i) for i in hidden]))
    )
    for k in (1, 4, 8):
        res = planning.plan(blocked, k)
        assert not set(res.suggested_ids) & set(reasons), (k, res.suggested_ids)
        assert all(mask[grid.index(i)] for i in res.suggested_ids)


def test_shipped_demo_rejects_the_candidate_behind_the_post(demo):
    mask, reasons = planning.usable_candidates(demo)
    assert reasons == {"grid-0100": reasons["grid-0100"]} and "fiducial_posts" in reasons["grid-0100"]
    assert mask.sum() == len(demo.candidates) - 1


def test_plan_asks_for_too_many(partial):
    n_usable = int(planning.usable_candidates(partial)[0].sum())
    with pytest.raises(InputError, match="usable candidate"):
        planning.plan(partial, n_usable + 1)
    with pytest.raises(InputError, match=">= 0"):
        planning.plan(partial, -1)


@pytest.mark.parametrize("name", SCENES)
def test_plan_runs_on_every_shipped_scene(name):
    scene = load_scene(ROOT / "scenes" / f"{name}.toml")
    res = planning.plan(scene, 2, seed=1)
    assert len(res.suggested_ids) <= 2 and set(res.suggested_ids) <= set(scene.candidates.ids)
    assert not set(res.suggested_ids) & set(res.rejected)
    assert set(res.baselines) == {"hull-corners", "random"}
    if name == "breadboard_vanwyk2018":  # every target sits on a fiducial: no set gains more than 2 % (planning.md)
        assert res.suggested_ids == () and "nothing is suggested" in res.note
        return
    assert len(res.suggested_ids) == 2
    # the optimiser's objective: never worse than the rules it is compared with
    assert res.predicted_after.rrbc_mm <= res.baselines["hull-corners"].rrbc_mm * (1 + 1e-9)
    assert res.predicted_after.rrbc_mm <= res.baselines["random"].rrbc_mm * (1 + 1e-9)
    js = res.to_json()
    json.dumps(js, allow_nan=False)


# ------------------------------------------------------------------------------------------------------
# the command line
# ------------------------------------------------------------------------------------------------------
def _run(capsys, *argv):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def test_cli_json_fields(capsys):
    rc, out, err = _run(capsys, "plan", ROOT / "scenes" / "peg_in_hole_cell.toml", "--add", 2, "--json")
    assert rc == 0, err
    js = json.loads(out)
    for key in (
        "coverage",
        "predicted_rmst_mm",
        "suggested",
        "predicted_rmst_after_mm",
        "coverage_per_target",
        "predicted",
        "predicted_after",
        "baselines",
        "suggested_ids",
        "rejected",
    ):
        assert key in js
    assert 0 <= js["coverage"] <= 1 and js["coverage"] == 1.0
    assert len(js["suggested"]) == 2 and all(len(p) == 3 for p in js["suggested"])
    assert js["predicted_rmst_mm"] == js["predicted"]["rrbc_mm"]
    assert js["predicted_rmst_after_mm"] <= js["predicted_rmst_mm"]
    assert set(js["coverage_per_target"]) == {"HOLE1", "HOLE2", "HOLE3", "HOLE4", "PEG1", "PEG2", "PEG3", "PEG4"}


def test_cli_table(capsys):
    rc, out, err = _run(capsys, "plan", ROOT / "scenes" / "demo_workcell.toml", "--add", 1)
    assert rc == 0, err
    assert "coverage" in out and "RRBC" in out and "suggested" in out and "grid-0100" in out


@pytest.mark.parametrize(
    "args, message",
    [
        (["--add", "-1"], "at least 0"),
        (["--add", "two"], "not an integer"),
        (["--add", "100000"], "usable candidate"),
    ],
)
def test_cli_bad_add_exits_2_with_one_line(capsys, args, message):
    rc, out, err = _run(capsys, "plan", ROOT / "scenes" / "demo_workcell.toml", *args)
    assert rc == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and message in err and "Traceback" not in err


def test_cli_bad_scene_exits_2(capsys, tmp_path):
    rc, out, err = _run(capsys, "plan", tmp_path / "missing.toml")
    assert rc == 2 and out == "" and len(err.strip().splitlines()) == 1
    bad = tmp_path / "bad.toml"
    bad.write_text((ROOT / "scenes" / "demo_workcell.toml").read_text().replace('units = "mm"', 'units = "inch"'))
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "demo_workcell.glb").write_bytes(
        (ROOT / "scenes" / "meshes" / "demo_workcell.glb").read_bytes()
    )
    rc, out, err = _run(capsys, "plan", bad, "--json")
    assert rc == 2 and out == "" and len(err.strip().splitlines()) == 1 and "units" in err


def test_a_plan_says_which_regions_stay_uncovered_why_and_where_a_fiducial_would_be_needed():
    """Issue 39, item 1: the breadboard's regions stand above its coplanar fiducials and no candidate lies above
    them: every region not wholly covered is named with "no usable candidate lies beyond it" and a place, which lies
    outside the hull of all fiducials and candidates (where one would have to be); regions the candidates could
    cover say so instead; the JSON and the text say the same."""
    from rrbc_core.interpolation.hull import covered

    scene = load_scene(ROOT / "scenes" / "breadboard_vanwyk2018.toml")
    res = planning.plan(scene, add=0)
    partial = [t for t, c in zip(scene.target_ids, res.coverage) if c < 1.0]
    assert partial and sorted(res.uncovered) == sorted(partial)
    usable = scene.candidates.positions[planning.usable_candidates(scene)[0]]
    everything = np.concatenate([scene.fiducials.positions, usable])
    for tid, why in res.uncovered.items():
        assert "no usable candidate lies beyond it" in why["reason"] and not why["candidates_could"], why
        where = np.array(why["needed_mm"])
        assert not covered(everything, where[None])[0], (tid, where)  # a place the candidates cannot reach
        assert f"{where[0] + 0.0:.0f}, {where[1] + 0.0:.0f}, {where[2] + 0.0:.0f}" in why["reason"]
    assert res.to_json()["uncovered_after"] == res.uncovered
    # the demo cell without most of its fiducials: its candidates could cover what the rest leave out
    demo = load_scene(ROOT / "scenes" / "demo_workcell.toml")
    few = demo.fiducials.positions[:4]
    thin = planning.plan(demo, add=0, fiducials_mm=few)
    assert thin.uncovered and all(
        w["candidates_could"] and "could bring it to" in w["reason"] for w in thin.uncovered.values()
    )
    assert set(thin.uncovered) == {t for t, c in zip(demo.target_ids, thin.coverage) if c < 1.0}
