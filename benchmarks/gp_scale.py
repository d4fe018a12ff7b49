"""gp at the sizes users reach (issue 41, item 2), in the user's own process, idle and with a busy core beside it.

- `gp_fit_1000`: `GP().fit` on 1000 noisy fiducials of a smooth field, then a prediction at 1000 queries, CPU time
  (`time.process_time`: the goal is CPU, which a busy core beside it does not inflate); scipy's imports done before.
  Baseline: the least any exact kriging of these fiducials costs, one Cholesky factorisation of the 1000 x 1000
  kernel matrix with the hyper-parameters given (and the same prediction). Goal: < 1 s CPU (loaded figure).
- `gp_fit_5000`: the same at 5000 fiducials (the largest gp takes, `interpolation.gp.MAX_FIDUCIALS`); the note gives
  the process's peak resident memory after it. Goal: accepted (it runs and returns finite predictions).
"""

from __future__ import annotations

import resource
import time

import numpy as np
from harness import both, row


def _field(n: int, seed: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    p = rng.uniform(0, 1000, (n, 3))
    p[:, 2] *= 0.2
    v = 0.3 * np.column_stack([np.sin(p[:, 0] / 200), np.cos(p[:, 1] / 250), np.sin((p[:, 0] + p[:, 1]) / 300)])
    q = rng.uniform(0, 1000, (1000, 3))
    q[:, 2] *= 0.2
    return p, v + rng.normal(0, 0.02, v.shape), q


def _cpu(fn) -> float:
    t0 = time.process_time()
    fn()
    return time.process_time() - t0


def _one_cholesky(p: np.ndarray, v: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Kriging with given hyper-parameters (Matérn 5/2, 250 mm, noise ratio 1e-2): the floor of any exact gp."""
    from scipy.linalg import cho_factor, cho_solve
    from scipy.spatial.distance import cdist

    def k(a, b):
        s = np.sqrt(5.0) * cdist(a, b) / 250.0
        return (1.0 + s + s * s / 3.0) * np.exp(-s)

    c = cho_factor(k(p, p) + 1e-2 * np.eye(len(p)), lower=True)
    return k(q, p) @ cho_solve(c, v - v.mean(axis=0)) + v.mean(axis=0)


def gp_scale(quick: bool) -> list[dict]:
    """Rows `gp_fit_1000` and `gp_fit_5000` (module docstring)."""
    import scipy.linalg
    import scipy.optimize
    import scipy.spatial.distance  # noqa: F401

    from rrbc_core.interpolation.gp import GP

    rows = []
    p, v, q = _field(1000)
    fit = lambda: GP().fit(p, v).values_at(q)
    base = min(_cpu(lambda: _one_cholesky(p, v, q)) for _ in range(3))
    idle, loaded = both(lambda: min(_cpu(fit) for _ in range(1 if quick else 3)))
    rows.append(
        row(
            "gp_fit_1000",
            idle,
            "s",
            loaded=loaded,
            baseline=base,
            goal="< 1 s CPU",
            met=loaded < 1.0,
            note="GP().fit on 1000 fiducials and a prediction at 1000 queries, CPU; baseline: one Cholesky with "
            "the hyper-parameters given",
        )
    )
    if not quick:
        p, v, q = _field(5000)
        out: list = []
        t = _cpu(lambda: out.append(GP().fit(p, v).values_at(q)))
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
        rows.append(
            row(
                "gp_fit_5000",
                t,
                "s",
                goal="accepted",
                met=bool(np.all(np.isfinite(out[0]))),
                note=f"GP().fit on 5000 fiducials and a prediction at 1000 queries, CPU; the benchmark process's "
                f"peak resident memory after it {peak:.0f} MB",
            )
        )
    return rows
