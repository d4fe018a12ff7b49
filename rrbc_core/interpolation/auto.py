"""`auto`: the interpolation chosen by the data, by cross-validation over the fiducials alone (issue 28).

Real data favour different methods (on one real robot IDW, the default, was the worst of four on every data set;
tps the best). `Auto().fit(points, values)` scores every candidate in `candidates` by K-fold cross-validation over
the fiducials — each fold's fiducials are predicted from the others, never from checks or targets — and fits the one
with the smallest CV error on all fiducials:

* folds: K = min(`FOLDS`, N) interleaved folds of a fixed permutation (seed 0), so the choice is reproducible;
* score: the RMS over all held-out fiducials of |predicted − measured correction|, mm;
* candidates: `none` (rigid: predict zero; so `auto` never picks a method whose CV error exceeds rigid's), IDW with
  k ∈ {1, 2, 4, 8} × p ∈ {1, 2, 3}, linear, tps with smoothing ∈ {0, 1e-3, 1e-2, 0.1, 1} (local units), and gp
  with either kernel when N ≤ `GP_MAX`; tps only when N ≤ `TPS_MAX`. A candidate that cannot be fitted on a fold
  (too few points, degenerate) is left out with its reason;
* ties (within 1e-9 mm) go to the earlier candidate in that order: the simpler method;
* rigid unless RRBC is clearly better: the best candidate is taken only if its mean squared CV error is below
  rigid's by more than one standard error of the paired per-fiducial difference; else `none` (on clean, noisy data
  a method can beat rigid on the fiducials by chance, and lose at the checks).

Cost: (K + 1) fits per candidate, up to 25 candidates; measured in the benchmark rows `auto_interpolation_*`
(docs/benchmarks.md: 0.34 s for 30 fiducials, 2.3 s for 150, 2.1 s for 1000 with gp left out). One fiducial cannot be cross-validated: it is
used as a constant (IDW).

The fitted object predicts like the chosen method and carries the choice (`AutoChoice`: method, table, folds).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.interpolation.base import FittedInterpolator, Prediction, check_data
from rrbc_core.interpolation.gp import GP
from rrbc_core.interpolation.idw import IDW, NoCorrection
from rrbc_core.interpolation.linear import Linear
from rrbc_core.interpolation.tps import TPS
from rrbc_core.option_specs import option_specs
from rrbc_core.runtime.threads import thread_limited

#: at most this many cross-validation folds
FOLDS = 10
#: gp (REML fit, O(N³) per fold) is a candidate up to this many fiducials, tps (dense solve) up to TPS_MAX
GP_MAX = 150
TPS_MAX = 1500
IDW_K = (1, 2, 4, 8)
IDW_POWER = (1.0, 2.0, 3.0)
TPS_SMOOTHING = (0.0, 1e-3, 1e-2, 0.1, 1.0)
TIE_MM = 1e-9


def candidates(n: int) -> list:
    """The candidate method objects for N fiducials, simplest first (module docstring)."""
    out: list = [NoCorrection()]
    out += [IDW(k=k, power=p) for k in IDW_K for p in IDW_POWER]
    out.append(Linear())
    if n <= TPS_MAX:
        out += [TPS(smoothing=s) for s in TPS_SMOOTHING]
    if n <= GP_MAX:
        out += [GP(kernel="matern52"), GP(kernel="se")]
    return out


def left_out(n: int) -> tuple[tuple[str, str], ...]:
    """(method, why) of the candidates not tried for N fiducials (`candidates`): `auto` says so rather than narrowing
    its choice without a word."""
    out = []
    if n > TPS_MAX:
        out.append(("tps", f"more than {TPS_MAX} fiducials (a dense solve per fold)"))
    if n > GP_MAX:
        out.append(("gp", f"more than {GP_MAX} fiducials (a likelihood fit, cubic in their number, per fold)"))
    return tuple(out)


def method_json(method) -> dict:
    """A method object as JSON: ``method`` and its options by flag (as `MethodOptions.interpolation_json`)."""
    out: dict[str, Any] = {"method": method.name}
    for spec in option_specs(method):
        out[spec.flag.replace("-", "_")] = getattr(method, spec.name)
    return out


@dataclass(frozen=True)
class CVRow:
    """One candidate's cross-validation: the method object, its CV RMS error (mm; None when it could not be fitted on
    some fold) and why not."""

    method: Any
    cv_rms_mm: float | None
    note: str = ""
    #: (N,) squared held-out error per fiducial, mm² (not in the JSON)
    squared: np.ndarray | None = field(default=None, repr=False, compare=False)

    def to_json(self) -> dict:
        out = {**method_json(self.method), "cv_rms_mm": self.cv_rms_mm}
        if self.note:
            out["note"] = self.note
        return out


@dataclass(frozen=True)
class AutoChoice:
    """What `auto` chose: ``method`` (a method object), ``table`` (a `CVRow` per candidate) and ``folds`` (K; 0 when
    there was nothing to cross-validate)."""

    method: Any
    table: tuple[CVRow, ...]
    folds: int
    #: (method, why) of candidates not tried (`left_out`)
    not_tried: tuple[tuple[str, str], ...] = ()

    def to_json(self) -> dict:
        """The ``interpolation`` JSON of a run with `--interpolation auto`: the chosen method and its options,
        ``selected_by`` "cross-validation over the fiducials", ``folds``, ``cv`` (the table) and ``not_tried``
        ([{method, why}])."""
        return {
            **method_json(self.method),
            "selected_by": "cross-validation over the fiducials",
            "folds": self.folds,
            "cv": [row.to_json() for row in self.table],
            "not_tried": [{"method": m, "why": why} for m, why in self.not_tried],
        }

    def describe(self) -> str:
        """One line for the text output and the app."""
        best = min((r.cv_rms_mm for r in self.table if r.cv_rms_mm is not None), default=None)
        rigid = next((r.cv_rms_mm for r in self.table if r.method.name == "none"), None)
        opts = ", ".join(f"{k}={v}" for k, v in method_json(self.method).items() if k != "method")
        head = f"auto chose {self.method.name}" + (f" ({opts})" if opts else "")
        if best is None or rigid is None:
            return head + " (too few fiducials to cross-validate)"
        skipped = "".join(f"; {m} not tried: {why}" for m, why in self.not_tried)
        return f"{head}: CV RMS {best:.4f} mm over {self.folds} folds of the fiducials (rigid {rigid:.4f} mm){skipped}"


def folds_of(n: int) -> np.ndarray:
    """Fold index (N,) of each fiducial: min(FOLDS, N) interleaved folds of a fixed permutation."""
    k = min(FOLDS, n)
    order = np.random.default_rng(0).permutation(n)
    out = np.empty(n, dtype=int)
    out[order] = np.arange(n) % k
    return out


def cross_validate(method, points: np.ndarray, values: np.ndarray, fold: np.ndarray) -> CVRow:
    """One candidate's K-fold CV error (module docstring)."""
    err = np.empty_like(values)
    for f in range(int(fold.max()) + 1):
        test = fold == f
        try:
            err[test] = method.fit(points[~test], values[~test]).predict(points[test]).values - values[test]
        except InputError as exc:
            return CVRow(method, None, str(exc).split(";")[0])
    if not np.all(np.isfinite(err)):
        return CVRow(method, None, "non-finite predictions")
    sq = np.sum(err**2, axis=1)
    return CVRow(method, float(np.sqrt(np.mean(sq))), squared=sq)


def clearly_better(row: CVRow, rigid: CVRow) -> bool:
    """Whether `row` beats rigid by more than one standard error of the paired per-fiducial difference of squared
    held-out errors."""
    if row.squared is None or rigid.squared is None:
        return False
    d = row.squared - rigid.squared
    se = float(np.std(d, ddof=1) / np.sqrt(len(d))) if len(d) > 1 else 0.0
    return float(np.mean(d)) < -se


@thread_limited
def choose(points, values) -> AutoChoice:
    """The candidate with the smallest CV error (ties: the simpler), with the table.

    Parameters
    ----------
    points : (N, 3) array_like
        Fiducial positions, sensor frame, mm.
    values : (N, 3) array_like
        Their corrections, mm.
    """
    p, v = check_data(points, values)
    if len(p) < 2:
        return AutoChoice(IDW(), (), 0)
    fold = folds_of(len(p))
    table = tuple(cross_validate(m, p, v, fold) for m in candidates(len(p)))
    scored = [(r.cv_rms_mm, r) for r in table if r.cv_rms_mm is not None]
    rigid = best = scored[0][1]  # `none` always scores
    best_rms = scored[0][0]
    for rms, r in scored[1:]:
        if rms < best_rms - TIE_MM:
            best, best_rms = r, rms
    if not clearly_better(best, rigid):
        best = rigid
    return AutoChoice(best.method, table, int(fold.max()) + 1, left_out(len(p)))


class _FittedAuto:
    """The chosen method fitted on all fiducials; ``choice`` says what was chosen and why."""

    method = "auto"

    def __init__(self, points: np.ndarray, values: np.ndarray) -> None:
        self.choice = choose(points, values)
        self.fitted: FittedInterpolator = self.choice.method.fit(points, values)
        self.n_fiducials = len(points)

    def __getattr__(self, name: str):  # hull, frame, …: the chosen method's
        return getattr(self.__dict__["fitted"], name)

    def predict(self, query) -> Prediction:
        return self.fitted.predict(query)

    def values_at(self, query) -> np.ndarray:
        return self.fitted.values_at(query)


@dataclass(frozen=True)
class Auto:
    """The interpolation chosen by K-fold cross-validation over the fiducials (module docstring). No options."""

    name: ClassVar[str] = "auto"

    def fit(self, points, values) -> _FittedAuto:
        p, v = check_data(points, values)
        return _FittedAuto(p, v)
