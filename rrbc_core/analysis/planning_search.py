"""Where fiducials can go and which to add: usable candidates (not buried in solids, visible to the sensor, within
the arm's reach) and the optimiser (greedy forward selection, then exchange from the best of the greedy set and the
simple rules' sets, on the predicted RMST with RRBC; coverage breaks ties), scoring many candidate sets at once. The
method: `planning`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core.analysis.planning_model import _SETS_PER_CHUNK, _cell, _fid_arrays, _Model
from rrbc_core.errors import InputError
from rrbc_core.interpolation.hull import covered
from rrbc_core.runtime.threads import thread_limited

#: A candidate inside a solid but within this distance (mm) of a surface lies on that surface (usable).
SURFACE_TOL_MM = 1.0


#: Exchange passes of the optimiser (each pass tries every swap once); it stops earlier when nothing improves.
_MAX_EXCHANGE_PASSES = 20


#: Relative improvement below which an exchange is not worth taking (guards against rounding cycles).
_IMPROVE_REL = 1e-9


#: Least relative drop of the predicted RMST for a suggestion to be made: the first-order prediction's own accuracy
#: (docs/theory.md §2.3 measured its noise term within 1-2 % of Monte Carlo), so a smaller predicted gain is not one.
MIN_GAIN = 0.02


# ------------------------------------------------------------------------------------------------------
# Candidates
# ------------------------------------------------------------------------------------------------------
def _buried(mesh, points: np.ndarray) -> dict:
    """{index: part name} for points inside a closed part of the mesh and deeper than SURFACE_TOL_MM below that
    part's surface. `visibility.inside_solids` screens; each flagged point is then tested part by part (open3d
    occupancy + unsigned distance to that part's surface), so a marker on a surface — even a surface of another
    part passing through it, like a table top through a block standing on it — stays usable."""
    import open3d as o3d

    from rrbc_core.models.visibility import inside_solids, raycasting_scene

    flagged = np.flatnonzero(inside_solids(mesh, points))
    if len(flagged) == 0:
        return {}
    v, f = np.asarray(mesh.vertices, float), np.asarray(mesh.faces)
    p = points[flagged]
    shift = p.mean(axis=0)
    q = o3d.core.Tensor(np.ascontiguousarray(p - shift, dtype=np.float32))
    out: dict = {}
    for name, start, stop in mesh.metadata.get("parts") or [("mesh", 0, len(f))]:
        if stop <= start:
            continue
        used, local = np.unique(f[start:stop], return_inverse=True)
        rc = raycasting_scene(v[used], local.reshape(-1, 3), shift)
        deep = rc.compute_occupancy(q, nsamples=3).numpy().astype(bool) & (
            rc.compute_distance(q).numpy().astype(float) > SURFACE_TOL_MM
        )
        for k in np.flatnonzero(deep):
            out.setdefault(int(flagged[k]), str(name))
    return out


def _unreachable(scene, positions: np.ndarray) -> dict:
    """{index: message} for points the error model cannot evaluate (e.g. out of the arm's reach)."""
    from rrbc_core.models.errormodels import PointSet
    from rrbc_core.models.kinematics import tool_down

    det = scene.error_model.deterministic()
    if not det.robot and not det.sensor:
        return {}

    def check(p):
        n = len(p)
        ps = PointSet(
            robot=p,
            sensor=scene.sensor_to_robot.apply_inverse(p),
            time=np.zeros(n),
            tool_rotation=np.broadcast_to(tool_down(scene.tool_yaw_deg), (n, 3, 3)),
            joint_seed=scene.joint_seed,
        )
        det.sample(ps, "robot", np.random.default_rng(0), 1)
        det.sample(ps, "sensor", np.random.default_rng(0), 1)

    try:
        check(positions)
        return {}
    except InputError:
        pass
    bad = {}
    for i, p in enumerate(positions):
        try:
            check(p[None])
        except InputError as exc:
            bad[i] = " ".join(str(exc).split())
    return bad


@thread_limited
def usable_candidates(scene) -> tuple[np.ndarray, dict]:
    """(mask (C,) over scene.candidates, {candidate id: reason}) — which candidate locations can hold a fiducial.

    Rejected: inside solid geometry (inside a closed mesh part, open3d occupancy, and more than SURFACE_TOL_MM
    below that part's surface — a marker on a surface is fine); hidden from the sensor (a ray
    from the sensor position is blocked by the mesh, `visibility.occluded_by`, 1 mm tolerance; skipped for a
    `ground_truth` sensor, which has no line of sight); not evaluable by the error model (e.g. out of the arm's
    reach). Positions: scene frame (robot base frame), mm.
    """
    from rrbc_core.models.visibility import occluded_by

    c = scene.candidates
    mask = np.ones(len(c), dtype=bool)
    reasons: dict = {}
    if len(c) == 0:
        return mask, reasons
    pos = c.positions
    mesh = scene.load_mesh()
    for i, part in _buried(mesh, pos).items():
        mask[i] = False
        reasons[c.ids[i]] = f"inside solid geometry ({part})"
    if scene.line_of_sight:
        occ = occluded_by(mesh, scene.sensor_position, pos)
        for i, o in enumerate(occ):
            if o is not None and mask[i]:
                mask[i] = False
                reasons[c.ids[i]] = f"hidden from the sensor by {o[0]} ({o[1]:.0f} mm from the sensor)"
    idx = np.flatnonzero(mask)
    for i, msg in _unreachable(scene, pos[idx]).items():
        mask[idx[i]] = False
        reasons[c.ids[idx[i]]] = f"cannot be evaluated: {msg}"
    return mask, reasons


# ------------------------------------------------------------------------------------------------------
# The optimiser
# ------------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class _Pool:
    """The base fiducials (always kept) and the usable candidates, with everything the fast objective needs.
    base_pos (B,3), cand_pos (C,3), query_pos (M,3): nominal positions, scene frame, mm (for the coverage)."""

    model: _Model
    base: tuple  # arrays for the base fiducials: sensor (B,3), corr, jac, cov, shared (B,)
    cand: tuple  # the same for the candidates (C, ...)
    base_pos: np.ndarray
    cand_pos: np.ndarray
    query_pos: np.ndarray
    target_pos: np.ndarray  # (T,3) the targets' own positions

    def stack(self, choices: np.ndarray) -> tuple:
        """Arrays for T fiducial sets: base + candidates `choices` (T, K) (indices into the candidates)."""
        t = choices.shape[0]
        out = []
        for b, c in zip(self.base, self.cand):
            picked = c[choices]
            out.append(np.concatenate([np.broadcast_to(b, (t,) + b.shape), picked], axis=1))
        return tuple(out)

    def rrbc(self, choices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Predicted RRBC RMST and its std (T,) for T sets of candidate indices (T, K)."""
        choices = np.asarray(choices, int).reshape(len(choices), -1)
        sq = np.concatenate(
            [
                self.model.rrbc_sq(*self.stack(choices[i : i + _SETS_PER_CHUNK]))
                for i in range(0, len(choices), _SETS_PER_CHUNK)
            ]
        )
        return self.model.rmst(sq)

    def covered(self, choices: np.ndarray) -> np.ndarray:
        """Fraction (T,) of the region samples (all targets weighted equally) inside the hull of each set."""
        choices = np.asarray(choices, int).reshape(len(choices), -1)
        return np.array(
            [covered(np.concatenate([self.base_pos, self.cand_pos[c]]), self.query_pos).mean() for c in choices]
        )

    def centres(self, choices: np.ndarray) -> np.ndarray:
        """Number (T,) of targets whose own position is inside the hull of each set."""
        choices = np.asarray(choices, int).reshape(len(choices), -1)
        return np.array(
            [covered(np.concatenate([self.base_pos, self.cand_pos[c]]), self.target_pos).sum() for c in choices]
        )

    def score(self, choices: np.ndarray, cover_first: bool = False) -> np.ndarray:
        """(T, 3) keys, smaller is better, compared in order: [−targets inside the hull (with `cover_first`, else
        0), predicted RRBC RMST, −coverage of the regions]. The objective is the RMST; coverage breaks ties, and
        with `cover_first` (`rrbc scene new`'s first fiducials) covering the targets comes first."""
        rmst = self.rrbc(choices)[0]
        first = -self.centres(choices).astype(float) if cover_first else np.zeros(len(rmst))
        return np.column_stack([first, rmst, -self.covered(choices)])

    def current(self) -> float:
        """The predicted RRBC RMST of the base fiducials alone (rigid without any)."""
        return float(self.rrbc(np.zeros((1, 0), int))[0][0])


def _pool(scene, base: np.ndarray, cand: np.ndarray, samples_per_target: int, seed: int) -> _Pool:
    cell, fi = _cell(scene, np.concatenate([base, cand]), None, samples_per_target, seed)
    model, rd = _Model.from_cell(cell)  # fi: the base fiducials, then the candidates
    pos = cell.robot[fi]
    arrays = _fid_arrays(model, rd, fi) + (model.shared_index(pos),)
    nb = len(base)
    return _Pool(
        model,
        tuple(a[:nb] for a in arrays),
        tuple(a[nb:] for a in arrays),
        pos[:nb],
        pos[nb:],
        cell.robot[cell.index("check")],
        np.asarray(scene.target_positions, float).reshape(-1, 3),
    )


def _best(keys: np.ndarray) -> int:
    """Index of the best of (T, 3) keys (`_Pool.score`): the smallest first key; then the smallest RMST, RMSTs
    within 1e-12 relative of it counted equal; then the largest coverage."""
    top = keys[:, 0] <= keys[:, 0].min()
    rmst = keys[:, 1]
    top &= rmst <= rmst[top].min() * (1 + 1e-12)
    idx = np.flatnonzero(top)
    return int(idx[np.argmin(keys[idx, 2])])


def _better(a: np.ndarray, b: np.ndarray) -> bool:
    """Key `a` better than key `b`: fewer uncovered targets first, then a lower RMST by more than `_IMPROVE_REL`."""
    if a[0] != b[0]:
        return bool(a[0] < b[0])
    return bool(a[1] < b[1] * (1 - _IMPROVE_REL))


def _exchange(pool: _Pool, chosen: list[int], n_cand: int, cover_first: bool, progress=None):
    """Fedorov-style exchange: swap one chosen candidate for an unused one while the key improves (`_better`).
    Returns (the set, its key (3,), sets evaluated)."""
    chosen = list(chosen)
    best = pool.score(np.array([chosen]), cover_first)[0]
    evaluated = 1
    for _ in range(_MAX_EXCHANGE_PASSES):
        improved = False
        for slot in range(len(chosen)):
            rest = np.array([i for i in range(n_cand) if i not in chosen], dtype=int)
            if len(rest) == 0:
                break
            trial = np.tile(chosen, (len(rest), 1))
            trial[:, slot] = rest
            keys = pool.score(trial, cover_first)
            evaluated += len(trial)
            j = _best(keys)
            if _better(keys[j], best):
                chosen[slot] = int(rest[j])
                best = keys[j]
                improved = True
        if progress:
            progress(1, "exchange")
        if not improved:
            break
    return chosen, best, evaluated


@dataclass(frozen=True, eq=False)
class Search:
    """What `_optimise` found: the chosen candidates (indices, possibly fewer than asked: only those that lower the
    predicted RMST), its predicted RRBC RMST, the current set's, the greedy path's RMST after each step, the rule
    sets' RMST (hull-corners; each random draw), how many sets were scored and which start exchange improved."""

    chosen: np.ndarray
    rmst: float
    current: float
    greedy_path: np.ndarray
    corners: float
    random_draws: np.ndarray
    evaluated: int
    started_from: str  # "greedy", "hull-corners" or "random"


def _optimise(pool: _Pool, n_cand: int, add: int, rule_sets: dict, progress=None, cover_first: bool = False) -> Search:
    """The suggestion for `add` fiducials: greedy forward selection on the key (`_Pool.score`), then exchange from
    the best of the greedy set and the rules' sets (`rule_sets`: "hull-corners" -> (add,) indices, "random" ->
    (D, add) draws), so the result is never worse than a rule's. If it is not predicted better than the current
    fiducials by at least `MIN_GAIN`, the best shorter greedy prefix that is, or nothing."""
    current = pool.current()
    chosen: list[int] = []
    path = []
    evaluated = 0
    for step in range(add):
        rest = np.array([i for i in range(n_cand) if i not in chosen], dtype=int)
        trial = np.column_stack([np.tile(chosen, (len(rest), 1)).reshape(len(rest), len(chosen)), rest])
        keys = pool.score(trial, cover_first)
        j = _best(keys)
        evaluated += len(trial)
        chosen.append(int(rest[j]))
        path.append(keys[j])
        if progress:
            progress(1, f"greedy {step + 1}/{add}")
    if add == 0:
        return Search(np.zeros(0, int), current, current, np.zeros(0), current, np.zeros(0), 0, "greedy")
    corners = np.asarray(rule_sets["hull-corners"], int)
    draws = np.asarray(rule_sets["random"], int).reshape(-1, add)
    c_key = pool.score(corners[None], cover_first)[0]
    d_keys = pool.score(draws, cover_first) if len(draws) else np.zeros((0, 3))
    evaluated += 1 + len(draws)
    starts = {"greedy": (chosen, path[-1]), "hull-corners": (list(corners), c_key)}
    if len(draws):
        k = _best(d_keys)
        starts["random"] = (list(draws[k]), d_keys[k])
    name = "greedy"
    for other in ("hull-corners", "random"):
        if other in starts and _better(starts[other][1], starts[name][1]):
            name = other
    best, key, n_ex = _exchange(pool, starts[name][0], n_cand, cover_first, progress)
    evaluated += n_ex
    rmst_path = np.array([p[1] for p in path])
    val = float(key[1])
    enough = current * (1 - MIN_GAIN)
    if val > enough:  # no set of `add` helps by more than the prediction's accuracy: a shorter prefix, or nothing
        k = int(np.argmin(rmst_path))
        if rmst_path[k] <= enough:
            best, val = chosen[: k + 1], float(rmst_path[k])
        else:
            best, val = [], current
    return Search(
        np.array(best, int), val, current, rmst_path, float(c_key[1]), d_keys[:, 1].astype(float), evaluated, name
    )


def _corner_choice(scene, cand_pos: np.ndarray, add: int) -> np.ndarray:
    """The "hull-corners" rule: the candidates nearest the 8 corners of the targets' bounding box, corners in
    farthest-first order (then, beyond 8, farthest-first over the remaining candidates)."""
    lo = np.min([t.region.bounds()[0] for t in scene.targets], axis=0)
    hi = np.max([t.region.bounds()[1] for t in scene.targets], axis=0)
    corners = np.array([[(lo, hi)[(k >> a) & 1][a] for a in range(3)] for k in range(8)])
    order = [0]
    while len(order) < 8:
        d = np.min(np.linalg.norm(corners[:, None] - corners[order][None], axis=2), axis=1)
        d[order] = -1
        order.append(int(np.argmax(d)))
    chosen: list[int] = []
    for k in order[: min(add, 8)]:
        d = np.linalg.norm(cand_pos - corners[k], axis=1)
        d[chosen] = np.inf
        chosen.append(int(np.argmin(d)))
    while len(chosen) < add:
        d = np.min(np.linalg.norm(cand_pos[:, None] - cand_pos[chosen][None], axis=2), axis=1)
        d[chosen] = -1
        chosen.append(int(np.argmax(d)))
    return np.array(chosen, dtype=int)
