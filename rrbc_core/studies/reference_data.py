"""Published measurements the simulation is held against: Van Wyk & Marvel (2018), Tables I–III.

Source: K. Van Wyk, J. A. Marvel, "Strategies for Improving and Evaluating Robot Registration Performance",
IEEE Trans. Autom. Sci. Eng. 15 (2018), doi:10.1109/TASE.2017.2720478 (NIST author manuscript PMC6508671).
The numbers live in `rrbc_core/data/vanwyk2018_tables.csv`, copied unchanged from the project's shared
reference folder; this module only parses them and derives what the paper implies but does not state
(the number of samples per method from Table I, the number of successful insertions from Table III).

Units: errors in mm, variances in mm², r dimensionless, p-values and PS probabilities.
"""

from __future__ import annotations

import csv
import functools
import io
from dataclasses import dataclass
from importlib import resources

import numpy as np
from scipy import special, stats

CITATION = (
    'K. Van Wyk, J. A. Marvel, "Strategies for Improving and Evaluating Robot Registration Performance", '
    "IEEE Trans. Autom. Sci. Eng. 15 (2018), doi:10.1109/TASE.2017.2720478 (NIST author manuscript PMC6508671), "
    "Tables I-III"
)

#: Peg test of Table III: 16 sites x (5 tries at 0 deg + 5 at 90 deg about z).
PEG_TRIES = 160
#: Confidence level of the binomial bound the paper uses for PS.
PEG_CONFIDENCE = 0.95
#: Peg-hole clearance of the Table III experiment (mm).
PEG_CLEARANCE_MM = 0.08


@dataclass(frozen=True)
class MeasuredRow:
    """One registration method's published statistics (Table II order)."""

    method: str
    order: int  # row in Table II (1..7)
    r: float  # Table I: Pearson r of translation error with distance from the origin of N
    p: float  # Table I: its p-value
    ks_p_vs_prev: float | None  # Table II: two-sample KS p-value against the previous Table II row (None: row 1)
    mean_mm: float  # Table II
    var_mm2: float  # Table II
    max_mm: float  # Table III
    ps: float  # Table III: probability of successful one-shot peg insertion (binomial bound)
    significant: dict  # the paper's significance marks (95 % CL), e.g. {"r": True, "mean": False}

    def as_dict(self) -> dict:
        return {
            "method": self.method,
            "mean_mm": self.mean_mm,
            "var_mm2": self.var_mm2,
            "max_mm": self.max_mm,
            "r": self.r,
            "p": self.p,
            "ks_p_vs_prev": self.ks_p_vs_prev,
            "ps": self.ps,
        }


def _float(text: str) -> float | None:
    return None if text.strip() == "" else float(text)


def parse_tables(text: str) -> tuple[MeasuredRow, ...]:
    """Rows of the CSV (comment lines start with '#'), sorted in Table II order."""
    lines = [ln for ln in io.StringIO(text) if ln.strip() and not ln.lstrip().startswith("#")]
    rows = []
    for d in csv.DictReader(lines):
        sig = {k[4:]: d[k].strip() == "1" for k in d if k.startswith("sig_")}
        rows.append(
            MeasuredRow(
                method=d["method"],
                order=int(d["table2_order"]),
                r=float(d["r"]),
                p=float(d["p"]),
                ks_p_vs_prev=_float(d["ks_p_vs_prev"]),
                mean_mm=float(d["mean_mm"]),
                var_mm2=float(d["var_mm2"]),
                max_mm=float(d["max_mm"]),
                ps=float(d["ps"]),
                significant=sig,
            )
        )
    return tuple(sorted(rows, key=lambda row: row.order))


def vanwyk2018() -> tuple[MeasuredRow, ...]:
    """The seven methods' published statistics, in Table II order."""
    text = resources.files("rrbc_core.data").joinpath("vanwyk2018_tables.csv").read_text(encoding="utf-8")
    return parse_tables(text)


def correlation_p(r: float, n: int) -> float:
    """Two-sided p-value of a Pearson correlation r from n samples (t test with n − 2 degrees of freedom)."""
    t = abs(r) * np.sqrt(n - 2) / np.sqrt(max(1.0 - r * r, 1e-300))
    return float(2.0 * stats.t.sf(t, n - 2))


def samples_consistent_with(r: float, p: float, n_range: range = range(10, 400)) -> list[int]:
    """Sample counts n for which a correlation that rounds to r (3 decimals) has a p-value that rounds to p."""
    out = []
    for n in n_range:
        lo = correlation_p(abs(r) + 0.0005, n)
        hi = correlation_p(max(abs(r) - 0.0005, 0.0), n)
        if lo - 0.0005 <= p <= hi + 0.0005:
            out.append(n)
    return out


def samples_per_method(rows=None) -> tuple[int, dict]:
    """The number of samples per method implied by Table I: the n consistent with every row whose p-value is
    informative (p > 0.0005; p = 0.000 fits any large n). Returns (n, {method: consistent n list})."""
    rows = vanwyk2018() if rows is None else rows
    per = {row.method: samples_consistent_with(row.r, row.p) for row in rows if row.p > 0.0005}
    common = set.intersection(*(set(v) for v in per.values())) if per else set()
    if not common:
        raise ValueError("no sample count is consistent with every Table I row")
    return max(common), per


def ps_bound(successes: int, tries: int = PEG_TRIES, confidence: float = PEG_CONFIDENCE) -> float:
    """The paper's PS: the p solving F(m − 1; n, p) = CL (F the binomial CDF, m successes of n tries). In closed
    form: F(m − 1; n, p) = I_{1−p}(n − m + 1, m) (the regularised incomplete beta), so p = 1 − I⁻¹_CL(n − m + 1, m);
    m = n gives F(n − 1; n, p) = 1 − pⁿ, so p = (1 − CL)^(1/n)."""
    return float(_ps_bounds(tries, confidence)[int(successes)]) if successes > 0 else 0.0


@functools.lru_cache(maxsize=8)
def _ps_bounds(tries: int, confidence: float) -> np.ndarray:
    """ps_bound for every success count 0..tries (read-only)."""
    m = np.arange(1, tries + 1)
    out = np.zeros(tries + 1)
    out[1:] = 1.0 - special.betaincinv(tries - m + 1, m, confidence)
    out.setflags(write=False)
    return out


def successes_from_ps(ps: float, tries: int = PEG_TRIES, confidence: float = PEG_CONFIDENCE) -> tuple[int, float]:
    """The success count m whose PS bound is nearest the published PS, and |bound − PS|."""
    bounds = _ps_bounds(tries, confidence)
    m = int(np.argmin(np.abs(bounds - ps)))
    return m, float(abs(bounds[m] - ps))
