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

A bound is computed on one noise draw, and a search over that draw favours the layout whose draw happened to give
low bounds: the chosen layout's bounds are then optimistic (on the demo scene the search draw's largest bound was
0.17 mm where other draws of the same layout gave a median near 0.27 mm). So a layout is judged on
`CONFIRM_DRAWS` fresh draws, seeded apart from the search's: a target's planned bound is the median over them of the
bound `rrbc correct` would print (the figure a user measuring this layout typically reads). The search's own draw
ranks the candidates at each step (cheap); once it says the tolerance is met, the `RERANK` best candidates of a step
are ranked on the fresh draws instead, and the search stops only when the fresh draws say every target is under.

What limits a target left over the tolerance is its largest budget share (`instrument`: the readings' own noise;
`registration`; `interpolation`: the correction between the fiducials), or `reach` when no fiducial near enough gave
it a bound at all. The scene's Monte Carlo confirms the predicted bounds (tests/analysis/test_planning_tolerance.py).
Units mm, robot frame.
"""

from __future__ import annotations

import copy
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from rrbc_core.correction.bounds import MIN_FIDUCIALS
from rrbc_core.errors import InputError

#: candidates considered: this many nearest any target
NEAR = 60
#: the most fiducials a plan takes
MAX_FIDUCIALS = 40
#: steps without a lower largest bound before the search stops
PATIENCE = 3
#: a tolerance below this (mm) is refused: no instrument here reads that finely
MIN_TOLERANCE_MM = 1e-4
#: fresh noise draws on which a layout's planned bounds are taken (module docstring)
CONFIRM_DRAWS = 9
#: candidates of a step ranked on the fresh draws once the search's own draw says the tolerance is met
RERANK = 3


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
    draws: int = CONFIRM_DRAWS  # fresh noise draws the bounds are the median of

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
            "draws": self.draws,
            "rule": f"greedy from {MIN_FIDUCIALS} spread candidates, each step the one lowering the largest bound most; "
            f"a target's bound is the median over {self.draws} fresh noise draws of the layout",
        }


def _largest(ev) -> float:
    b = ev.bounds.rrbc.bound95_mm if ev.bounds is not None else np.array([np.inf])
    return float(np.max(np.where(np.isfinite(b), b, np.inf))) if len(b) else 0.0


@dataclass(frozen=True)
class DrawnBounds:
    """A layout's bounds over the fresh draws: per target the median bound (inf: no bound in half the draws or
    more) and the median of each budget share."""

    bound95_mm: np.ndarray  # (T,)
    budget_mm: dict  # name -> (T,)

    @property
    def largest(self) -> float:
        return float(np.max(self.bound95_mm)) if len(self.bound95_mm) else 0.0

    def limit(self, i: int, tol: float) -> str:
        if not np.isfinite(self.bound95_mm[i]):
            return "reach"
        if self.bound95_mm[i] < tol:
            return ""
        parts = {k: float(v[i]) for k, v in self.budget_mm.items()}
        return max(parts, key=lambda k: parts[k])


def fresh_seeds(seed: int) -> list[int]:
    """The `CONFIRM_DRAWS` seeds of the fresh draws for a session seeded `seed` (apart from it and from small
    seeds)."""
    return [int(x) for x in np.random.SeedSequence([int(seed), CONFIRM_DRAWS]).generate_state(CONFIRM_DRAWS)]


def drawn_bounds(session, seeds) -> DrawnBounds:
    """The session's layout evaluated once per seed (its seed restored after): per target the median RRBC bound
    (a draw without a bound for a target counts as infinite) and the median of each budget share."""
    own = session.settings.seed
    evaluations = []
    try:
        for seed in seeds:
            session.settings = session.settings.replace(seed=int(seed))
            evaluations.append(session.evaluate())
    finally:
        session.settings = session.settings.replace(seed=own)
    n = len(session.layout["targets"].ids)
    b = np.array([e.bounds.rrbc.bound95_mm if e.bounds is not None else np.full(n, np.inf) for e in evaluations])
    bound = np.median(np.where(np.isfinite(b), b, np.inf), axis=0)
    names = sorted({k for e in evaluations if e.bounds is not None for k in e.bounds.rrbc.budget_mm})
    shares = [e.bounds.rrbc.budget_mm for e in evaluations if e.bounds is not None]
    with warnings.catch_warnings():  # a target without a bound in any draw: its shares stay NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        budget = {k: np.nanmedian(np.array([d.get(k, np.full(n, np.nan)) for d in shares]), axis=0) for k in names}
    return DrawnBounds(bound, budget)


def plan_to_tolerance(
    scene, tolerance_mm: float, max_fiducials: int = MAX_FIDUCIALS, start=None, progress=None
) -> TolerancePlan:
    """The fewest candidates bringing every target's 95 % bound under `tolerance_mm` (module docstring).

    `start`: an `ExplorerSession` of the scene as the user has it now (the app: targets and registration points
    moved, candidates added); its registration points, targets and candidates are used (it is not changed).
    Without it, the scene as written. `progress`: called `(1, label)` after the start and after each greedy step (at
    most `max_fiducials - MIN_FIDUCIALS + 1` calls), the label saying how many fiducials and the largest bound.

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

    def place(chosen: list[int]) -> None:
        session.layout = {
            **session.layout,
            "fiducials": Group(tuple(ids[k] for k in chosen), pool[chosen].reshape(-1, 3)),
        }

    def evaluate(chosen: list[int]):
        place(chosen)
        return session.evaluate()

    fresh = fresh_seeds(session.settings.seed)

    def confirm(chosen: list[int]) -> DrawnBounds:
        place(chosen)
        return drawn_bounds(session, fresh)

    # 1. a spread start: farthest-point sampling from the candidate nearest the targets' centre
    chosen = [int(np.argmin(np.linalg.norm(pool - targets.mean(axis=0), axis=1)))]
    while len(chosen) < min(MIN_FIDUCIALS, len(pool)):
        d = np.min(np.linalg.norm(pool[:, None, :] - pool[chosen][None], axis=2), axis=1)
        chosen.append(int(np.argmax(d)))

    def report(value: float) -> None:
        if progress is not None:
            progress(1, f"planning: {len(chosen)} fiducials, largest bound {value:.3g} mm")

    searched = _largest(evaluate(chosen))
    conf = confirm(chosen) if searched < tol else None
    report(searched if conf is None else conf.largest)
    best = {"search": searched, "fresh": conf.largest if conf is not None else np.inf}
    stale = 0
    # 2. greedy: the candidate lowering the largest bound most (on the search's draw; on the fresh draws once the
    #    search's draw says the tolerance is met)
    while (conf is None or conf.largest >= tol) and len(chosen) < min(max_fiducials, len(pool)) and stale < PATIENCE:
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
        trials.sort()
        if trials[0][0] < tol:
            ranked = [(c.largest, k, c) for _, k in trials[:RERANK] for c in [confirm(chosen + [k])]]
            value, k, conf = min(ranked, key=lambda r: (r[0], r[1]))
            currency = "fresh"
        else:
            (value, k), conf, currency = trials[0], None, "search"
        chosen.append(k)
        stale = stale + 1 if value >= best[currency] else 0
        best[currency] = min(best[currency], value)
        report(value)
    if conf is None:
        conf = confirm(chosen)
    place(chosen)
    bound = conf.bound95_mm
    return TolerancePlan(
        tol,
        bool(np.all(np.isfinite(bound)) and conf.largest < tol),
        tuple(ids[k] for k in chosen),
        pool[chosen].reshape(-1, 3),
        tuple(session.layout["targets"].ids),
        np.where(np.isfinite(bound), bound, np.nan),
        {k: v.copy() for k, v in conf.budget_mm.items()},
        tuple(conf.limit(i, tol) for i in range(len(bound))),
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
    lines.append(f"targets: 95 % bound (mm; the median over {res.draws} noise draws of the layout) and what limits it")
    for t in j["targets"]:
        b = "-" if t["bound95_mm"] is None else f"{t['bound95_mm']:.4f}"
        lines.append(f"  {t['id']:<10} {b:>9}  {'under' if t['under'] else (t['limit'] or '')}")
    return "\n".join(lines) + "\n"


@dataclass(frozen=True)
class PlanCheck:
    """A plan measured again by the scene's Monte Carlo (`monte_carlo_check`)."""

    within_planned: float  # share of target draws whose RRBC error lies within the planned bound
    within_own: float  # share within the bound `rrbc correct` gives on that draw
    draws: int  # target draws (targets x seeds)


def monte_carlo_check(scene, plan: TolerancePlan, seeds: Sequence[int] = tuple(range(1, 41))) -> PlanCheck:
    """The planned layout measured with other noise draws (`seeds`; the plan's own fresh seeds are large numbers
    drawn from the scene's seed): each target's RRBC error (robot frame, mm) against the bound the plan predicted and
    against the bound of that draw."""
    from rrbc_core.session.evaluation import Group
    from rrbc_core.session.explorer import ExplorerSession

    session = ExplorerSession.from_scene(scene)
    session.layout = {**session.layout, "fiducials": Group(plan.fiducial_ids, plan.fiducial_positions)}
    planned, own = [], []
    for seed in seeds:
        ev = session.update(seed=int(seed))
        planned += list(ev.targets.error_rrbc <= plan.bound95_mm)
        bound = ev.bounds.rrbc.bound95_mm if ev.bounds is not None else np.full(len(ev.targets.ids), np.nan)
        own += list(ev.targets.error_rrbc <= bound)  # no bound: not within
    return PlanCheck(float(np.mean(planned)), float(np.mean(own)), len(planned))
