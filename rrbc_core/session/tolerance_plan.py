"""Planning to a tolerance: the fewest fiducials, from a scene's usable candidates, that bring every target's 95 %
bound under a tolerance (`rrbc plan SCENE --tolerance T`), or why no choice can.

The bound is the one `rrbc correct` and the app give (`correction.bounds`), on the data the scene's measurement
model gives the layout (`session.explorer.ExplorerSession`, scene mode, the scene's seed): registration points as
the scene has them, fiducials only from the candidates, its targets. The search is greedy:

1. `MIN_FIDUCIALS` candidates spread over the targets (farthest-point sampling among the `NEAR` usable candidates
   nearest any target, from the one nearest their centre): fewer cannot be cross-validated, so give no RRBC bound;
2. then, one at a time, the candidate whose addition lowers the largest bound over the targets most (a target with
   no bound counts as infinitely far), until every bound is under the tolerance, no candidate lowers it for
   `PATIENCE` steps, or the candidates run out.

What limits a target left over the tolerance is its largest budget share (`instrument`: the readings' own noise;
`registration`; `interpolation`: the correction between the fiducials), or `reach` when no fiducial near enough gave
it a bound at all. The scene's Monte Carlo confirms the predicted bounds (tests/analysis/test_planning_tolerance.py).
Units mm, robot frame.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from rrbc_core.correction.bounds import MIN_FIDUCIALS
from rrbc_core.errors import InputError

#: candidates considered: this many nearest any target
NEAR = 60
#: steps without a lower largest bound before the search stops
PATIENCE = 3
#: a tolerance below this (mm) is refused: no instrument here reads that finely
MIN_TOLERANCE_MM = 1e-4


@dataclass(frozen=True)
class TolerancePlan:
    """The outcome of `plan_to_tolerance` (module docstring)."""

    tolerance_mm: float
    met: bool
    fiducial_ids: tuple[str, ...]
    fiducial_positions: np.ndarray
    target_ids: tuple[str, ...]
    bound95_mm: np.ndarray  # (T,) NaN: no bound
    budget_mm: dict
    limits: tuple[str, ...]  # per target over the tolerance: what limits it ("" when under)
    candidates_considered: int

    def to_json(self) -> dict:
        return {
            "tolerance_mm": self.tolerance_mm,
            "met": self.met,
            "count": len(self.fiducial_ids),
            "fiducials": [
                {"id": pid, "position": p.tolist()} for pid, p in zip(self.fiducial_ids, self.fiducial_positions)
            ],
            "targets": [
                {
                    "id": pid,
                    "bound95_mm": None if not np.isfinite(b) else float(b),
                    "budget_mm": None if not np.isfinite(b) else {k: float(v[i]) for k, v in self.budget_mm.items()},
                    "under": bool(np.isfinite(b) and b < self.tolerance_mm),
                    "limit": self.limits[i] or None,
                }
                for i, (pid, b) in enumerate(zip(self.target_ids, self.bound95_mm))
            ],
            "limits": sorted({x for x in self.limits if x}),
            "candidates_considered": self.candidates_considered,
            "rule": f"greedy from {MIN_FIDUCIALS} spread candidates, each step the one lowering the largest bound most",
        }


def _largest(ev) -> float:
    b = ev.bounds.rrbc.bound95_mm if ev.bounds is not None else np.array([np.inf])
    return float(np.max(np.where(np.isfinite(b), b, np.inf))) if len(b) else 0.0


def _limit(ev, i: int, tol: float) -> str:
    b = ev.bounds.rrbc
    if not np.isfinite(b.bound95_mm[i]):
        return "reach"
    if b.bound95_mm[i] < tol:
        return ""
    parts = {k: float(v[i]) for k, v in b.budget_mm.items()}
    return max(parts, key=lambda k: parts[k])


def plan_to_tolerance(scene, tolerance_mm: float, max_fiducials: int = 40, start=None) -> TolerancePlan:
    """The fewest candidates bringing every target's 95 % bound under `tolerance_mm` (module docstring).

    `start`: an `ExplorerSession` of the scene as the user has it now (the app: targets and registration points
    moved, candidates added); its registration points, targets and candidates are used (it is not changed).
    Without it, the scene as written.

    Raises
    ------
    InputError
        A tolerance that is not a positive finite number, or a scene without usable candidates.
    """
    from rrbc_core.analysis.planning import usable_candidates
    from rrbc_core.session.evaluation import Group
    from rrbc_core.session.explorer import ExplorerSession

    tol = float(tolerance_mm)
    if not np.isfinite(tol) or tol < MIN_TOLERANCE_MM:
        raise InputError(f"--tolerance {tolerance_mm}: give a bound in mm of at least {MIN_TOLERANCE_MM:g}")
    if start is not None:
        from rrbc_core.session.planning_view import planning_scene

        scene = planning_scene(start)
    mask, _ = usable_candidates(scene)
    cands = np.asarray(scene.candidates.positions, float).reshape(-1, 3)[mask]
    cand_ids = [pid for pid, ok in zip(scene.candidates.ids, mask) if ok]
    if len(cands) < MIN_FIDUCIALS:
        raise InputError(
            f"{scene.path}: {len(cands)} usable candidates; a bound needs at least {MIN_FIDUCIALS} fiducials"
        )
    session = ExplorerSession.from_scene(scene) if start is None else copy.copy(start)
    targets = session.layout["targets"].positions
    near = np.argsort(np.min(np.linalg.norm(cands[:, None, :] - targets[None], axis=2), axis=1))[:NEAR]
    pool = cands[near]
    taken = set(session.layout["registration"].ids) | set(session.layout["targets"].ids)
    ids = [str(cand_ids[k]) if str(cand_ids[k]) not in taken else f"{cand_ids[k]}_candidate" for k in near]

    def evaluate(chosen: list[int]):
        session.layout = {
            **session.layout,
            "fiducials": Group(tuple(ids[k] for k in chosen), pool[chosen].reshape(-1, 3)),
        }
        return session.evaluate()

    # 1. a spread start: farthest-point sampling from the candidate nearest the targets' centre
    chosen = [int(np.argmin(np.linalg.norm(pool - targets.mean(axis=0), axis=1)))]
    while len(chosen) < min(MIN_FIDUCIALS, len(pool)):
        d = np.min(np.linalg.norm(pool[:, None, :] - pool[chosen][None], axis=2), axis=1)
        chosen.append(int(np.argmax(d)))
    ev = evaluate(chosen)
    best = _largest(ev)
    stale = 0
    # 2. greedy: the candidate lowering the largest bound most
    while best >= tol and len(chosen) < min(max_fiducials, len(pool)) and stale < PATIENCE:
        trials = []
        for k in range(len(pool)):
            if k in chosen:
                continue
            try:
                trials.append((_largest(evaluate(chosen + [k])), k))
            except InputError:  # out of the arm's reach: not a usable fiducial here
                continue
        if not trials:
            break
        value, k = min(trials)
        chosen.append(k)
        stale = stale + 1 if value >= best else 0
        best = min(best, value)
    ev = evaluate(chosen)
    b = ev.bounds.rrbc
    limits = tuple(_limit(ev, i, tol) for i in range(len(ev.targets.ids)))
    return TolerancePlan(
        tol,
        bool(np.all(np.isfinite(b.bound95_mm)) and np.all(b.bound95_mm < tol)),
        tuple(ids[k] for k in chosen),
        pool[chosen].reshape(-1, 3),
        tuple(ev.targets.ids),
        b.bound95_mm.copy(),
        dict(b.budget_mm),
        limits,
        len(pool),
    )


def tolerance_text(res: TolerancePlan) -> str:
    """The text of `rrbc plan --tolerance`."""
    j = res.to_json()
    head = (
        f"{j['count']} fiducials bring every target's 95 % bound under {res.tolerance_mm:g} mm"
        if res.met
        else f"no choice of the {res.candidates_considered} candidates nearest the targets brings every target's "
        f"95 % bound under {res.tolerance_mm:g} mm; limited by: {', '.join(j['limits'])}"
    )
    lines = [head, "fiducials (robot frame, mm):"]
    lines += [f"  {f['id']:<10} [{', '.join(f'{v:9.2f}' for v in f['position'])}]" for f in j["fiducials"]]
    lines.append("targets: 95 % bound (mm) and what limits it")
    for t in j["targets"]:
        b = "-" if t["bound95_mm"] is None else f"{t['bound95_mm']:.4f}"
        lines.append(f"  {t['id']:<10} {b:>9}  {'under' if t['under'] else (t['limit'] or '')}")
    return "\n".join(lines) + "\n"
