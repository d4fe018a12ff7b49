"""Compiled per-trial kernel of the Monte Carlo's default chain: least-squares registration + RRBC with IDW.

`rrbc_batch("least-squares", "idw", ...)` (no weights) runs here: one compiled loop over trials (numba, made for
exactly this: numeric Python loops compiled to machine code) instead of numpy calls over (T, N, 3) stacks, whose
per-call overhead and small-axis reductions cost more than the arithmetic (benchmarks/run.py,
`mc_throughput_ls_rrbc`, holds it against a per-trial numpy loop). The first call on a machine compiles it; the
machine code is cached on disk beside this file (numba's cache), so later processes only load it.

Per trial, the same arithmetic as the core (`registration.kabsch`, `rrbc.fiducial_corrections`,
`interpolation.IDW`), to rounding:

- Kabsch with the reflection fix: centroids, H = Σ (s − s̄)(b − b̄)ᵀ, an SVD of the 3x3 H by one-sided (Hestenes)
  Jacobi rotations — orthogonalise H's columns, H V = U Σ; exact to a few ulps, rank-deficient H included
  (coplanar points: u₃ = u₁ × u₂) — then R = V diag(1, 1, det V) Uᵀ with a proper U, which is the core's
  V diag(1, 1, sign det(V Uᵀ)) Uᵀ for any SVD of H; t = b̄ − R s̄.
- corrections e_i = Rᵀ(b_i − t) − s_i (sensor frame);
- IDW: per query the k nearest fiducials by squared 3-D distance (ties: the lower index), weights (d₀/d_j)^p
  normalised (d₀ the nearest, as the core writes them; computed as (d₀²/d_j²)^(p/2)); a query closer than EXACT_MM to a fiducial takes the mean
  correction of every fiducial that close.

Shapes are checked by the caller (`batch.rrbc_batch`), which also makes the value checks with the by-products
the kernel returns (finiteness per trial and input, deviation from trial 0's layout). Import this module
lazily (it imports numba).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, error_model="python")
def _svd3(h, u, s, v, a, warm):  # pragma: no cover - compiled; tested through ls_idw
    """SVD of the 3x3 h: h v = u diag(s), s descending, u proper. warm: v holds the previous trial's V, used
    (re-orthonormalised) as the start, which a neighbouring trial's H needs 1-2 sweeps from; else v = I."""
    if warm:
        for j in range(3):  # Gram-Schmidt: rounding never accumulates from trial to trial
            for k in range(j):
                d = v[0, j] * v[0, k] + v[1, j] * v[1, k] + v[2, j] * v[2, k]
                for i in range(3):
                    v[i, j] -= d * v[i, k]
            nrm = np.sqrt(v[0, j] * v[0, j] + v[1, j] * v[1, j] + v[2, j] * v[2, j])
            if not nrm > 0.5:  # a previous trial's non-finite input: start cold
                warm = False
                break
            for i in range(3):
                v[i, j] /= nrm
    if not warm:
        for i in range(3):
            for j in range(3):
                v[i, j] = 1.0 if i == j else 0.0
    for i in range(3):
        for j in range(3):
            a[i, j] = h[i, 0] * v[0, j] + h[i, 1] * v[1, j] + h[i, 2] * v[2, j]
    for _ in range(40):
        off = 0.0
        for p in range(2):
            for q in range(p + 1, 3):
                alpha = a[0, p] * a[0, p] + a[1, p] * a[1, p] + a[2, p] * a[2, p]
                beta = a[0, q] * a[0, q] + a[1, q] * a[1, q] + a[2, q] * a[2, q]
                gamma = a[0, p] * a[0, q] + a[1, p] * a[1, q] + a[2, p] * a[2, q]
                if gamma == 0.0 or alpha == 0.0 or beta == 0.0:
                    continue
                rel = abs(gamma) / np.sqrt(alpha * beta)
                if rel > off:
                    off = rel
                if rel < 1e-17:
                    continue
                zeta = (beta - alpha) / (2.0 * gamma)
                t = (1.0 if zeta >= 0.0 else -1.0) / (abs(zeta) + np.sqrt(1.0 + zeta * zeta))
                c = 1.0 / np.sqrt(1.0 + t * t)
                sn = c * t
                for i in range(3):
                    ap, aq = a[i, p], a[i, q]
                    a[i, p] = c * ap - sn * aq
                    a[i, q] = sn * ap + c * aq
                    vp, vq = v[i, p], v[i, q]
                    v[i, p] = c * vp - sn * vq
                    v[i, q] = sn * vp + c * vq
        if off < 1e-15:
            break
    for j in range(3):
        s[j] = np.sqrt(a[0, j] * a[0, j] + a[1, j] * a[1, j] + a[2, j] * a[2, j])
    for i in range(2):  # sort descending (columns of a and v with them)
        for j in range(2 - i):
            if s[j] < s[j + 1]:
                s[j], s[j + 1] = s[j + 1], s[j]
                for r in range(3):
                    a[r, j], a[r, j + 1] = a[r, j + 1], a[r, j]
                    v[r, j], v[r, j + 1] = v[r, j + 1], v[r, j]
    for j in range(2):
        for r in range(3):
            u[r, j] = a[r, j] / s[j] if s[j] > 0.0 else 0.0  # s = 0: a degenerate trial the caller refuses
    u[0, 2] = u[1, 0] * u[2, 1] - u[2, 0] * u[1, 1]
    u[1, 2] = u[2, 0] * u[0, 1] - u[0, 0] * u[2, 1]
    u[2, 2] = u[0, 0] * u[1, 1] - u[1, 0] * u[0, 1]


@njit(cache=True, error_model="python")
def _ls_idw(
    reg_s,
    reg_b,
    fid_s,
    fid_b,
    q,
    k,
    power,
    exact_mm,
    a_out,
    t_out,
    e_out,
    c_out,
    rigid_out,
    rrbc_out,
    finite_out,
    dev_out,
    fid_sum,
    q_sum,
):  # pragma: no cover - compiled; tested against the core in tests/simulation/test_batch.py
    n_t, n_r = reg_s.shape[0], reg_s.shape[1]
    n_f, n_q = fid_s.shape[1], q.shape[1]
    h = np.empty((3, 3))
    u = np.empty((3, 3))
    s = np.empty(3)
    v = np.empty((3, 3))
    r = np.empty((3, 3))
    sa = np.empty((3, 3))
    d2 = np.empty(n_f)
    e = np.empty((n_f, 3))
    idx = np.empty(k, np.int64)
    dk = np.empty(k)
    fid_sum[:, :] = 0.0
    q_sum[:, :] = 0.0
    for tt in range(n_t):
        # by-products for the caller's checks: finiteness of each input, each registration set's deviation from
        # trial 0's layout, and the sums behind the trial-mean hull
        # x - x is 0 for finite x and NaN otherwise: the sums below stay exactly 0 only for finite inputs
        z0 = z1 = z2 = z3 = z4 = 0.0
        dev_s = dev_b = 0.0
        for n in range(n_r):
            for c in range(3):
                x, y = reg_s[tt, n, c], reg_b[tt, n, c]
                z0 += x - x
                z1 += y - y
                dx, dy = x - reg_s[0, n, c], y - reg_b[0, n, c]
                dev_s += dx * dx
                dev_b += dy * dy
        dev_out[tt, 0], dev_out[tt, 1] = np.sqrt(dev_s), np.sqrt(dev_b)
        for f in range(n_f):
            for c in range(3):
                x, y = fid_s[tt, f, c], fid_b[tt, f, c]
                z2 += x - x
                z3 += y - y
                fid_sum[f, c] += x
        for m in range(n_q):
            for c in range(3):
                x = q[tt, m, c]
                z4 += x - x
                q_sum[m, c] += x
        finite_out[tt, 0], finite_out[tt, 1], finite_out[tt, 2] = z0 == 0.0, z1 == 0.0, z2 == 0.0
        finite_out[tt, 3], finite_out[tt, 4] = z3 == 0.0, z4 == 0.0
        s0 = s1 = s2 = b0 = b1 = b2 = 0.0
        for n in range(n_r):
            s0 += reg_s[tt, n, 0]
            s1 += reg_s[tt, n, 1]
            s2 += reg_s[tt, n, 2]
            b0 += reg_b[tt, n, 0]
            b1 += reg_b[tt, n, 1]
            b2 += reg_b[tt, n, 2]
        s0, s1, s2, b0, b1, b2 = s0 / n_r, s1 / n_r, s2 / n_r, b0 / n_r, b1 / n_r, b2 / n_r
        h00 = h01 = h02 = h10 = h11 = h12 = h20 = h21 = h22 = 0.0
        for n in range(n_r):
            x0, x1, x2 = reg_s[tt, n, 0] - s0, reg_s[tt, n, 1] - s1, reg_s[tt, n, 2] - s2
            y0, y1, y2 = reg_b[tt, n, 0] - b0, reg_b[tt, n, 1] - b1, reg_b[tt, n, 2] - b2
            h00 += x0 * y0
            h01 += x0 * y1
            h02 += x0 * y2
            h10 += x1 * y0
            h11 += x1 * y1
            h12 += x1 * y2
            h20 += x2 * y0
            h21 += x2 * y1
            h22 += x2 * y2
        h[0, 0], h[0, 1], h[0, 2] = h00, h01, h02
        h[1, 0], h[1, 1], h[1, 2] = h10, h11, h12
        h[2, 0], h[2, 1], h[2, 2] = h20, h21, h22
        _svd3(h, u, s, v, sa, tt > 0)
        detv = (
            v[0, 0] * (v[1, 1] * v[2, 2] - v[1, 2] * v[2, 1])
            - v[0, 1] * (v[1, 0] * v[2, 2] - v[1, 2] * v[2, 0])
            + v[0, 2] * (v[1, 0] * v[2, 1] - v[1, 1] * v[2, 0])
        )
        sg = 1.0 if detv >= 0.0 else -1.0
        for i in range(3):
            for j in range(3):
                r[i, j] = v[i, 0] * u[j, 0] + v[i, 1] * u[j, 1] + sg * v[i, 2] * u[j, 2]
        r00, r01, r02 = r[0, 0], r[0, 1], r[0, 2]
        r10, r11, r12 = r[1, 0], r[1, 1], r[1, 2]
        r20, r21, r22 = r[2, 0], r[2, 1], r[2, 2]
        t0 = b0 - (r00 * s0 + r01 * s1 + r02 * s2)
        t1 = b1 - (r10 * s0 + r11 * s1 + r12 * s2)
        t2 = b2 - (r20 * s0 + r21 * s1 + r22 * s2)
        t_out[tt, 0], t_out[tt, 1], t_out[tt, 2] = t0, t1, t2
        for i in range(3):
            for j in range(3):
                a_out[tt, i, j] = r[i, j]
        for f in range(n_f):
            x0, x1, x2 = fid_b[tt, f, 0] - t0, fid_b[tt, f, 1] - t1, fid_b[tt, f, 2] - t2
            e[f, 0] = r00 * x0 + r10 * x1 + r20 * x2 - fid_s[tt, f, 0]
            e[f, 1] = r01 * x0 + r11 * x1 + r21 * x2 - fid_s[tt, f, 1]
            e[f, 2] = r02 * x0 + r12 * x1 + r22 * x2 - fid_s[tt, f, 2]
            e_out[tt, f, 0], e_out[tt, f, 1], e_out[tt, f, 2] = e[f, 0], e[f, 1], e[f, 2]
        for m in range(n_q):
            q0, q1, q2 = q[tt, m, 0], q[tt, m, 1], q[tt, m, 2]
            for f in range(n_f):  # every distance first (a loop the compiler vectorises) ...
                dx, dy, dz = q0 - fid_s[tt, f, 0], q1 - fid_s[tt, f, 1], q2 - fid_s[tt, f, 2]
                d2[f] = dx * dx + dy * dy + dz * dz
            cnt = 0
            for f in range(n_f):  # ... then the k smallest, by insertion
                dd = d2[f]
                if cnt < k:
                    pos = cnt
                    cnt += 1
                elif dd < dk[k - 1]:
                    pos = k - 1
                else:
                    continue
                while pos > 0 and dk[pos - 1] > dd:
                    dk[pos] = dk[pos - 1]
                    idx[pos] = idx[pos - 1]
                    pos -= 1
                dk[pos] = dd
                idx[pos] = f
            c0 = c1 = c2 = 0.0
            if (
                dk[0] < exact_mm * exact_mm and np.sqrt(dk[0]) < exact_mm
            ):  # on a fiducial: the mean correction of all that close
                ws = 0.0
                for f in range(n_f):
                    if np.sqrt(d2[f]) < exact_mm:
                        ws += 1.0
                        c0 += e[f, 0]
                        c1 += e[f, 1]
                        c2 += e[f, 2]
            else:
                ws = 0.0
                d0 = dk[0]  # > EXACT_MM², so no division by zero (numba's max() is slow here: not used)
                for j in range(cnt):
                    w = d0 / dk[j]  # (d0/dj)^2
                    if power != 2.0:
                        w = w ** (0.5 * power)
                    ws += w
                    c0 += w * e[idx[j], 0]
                    c1 += w * e[idx[j], 1]
                    c2 += w * e[idx[j], 2]
            c0, c1, c2 = c0 / ws, c1 / ws, c2 / ws
            c_out[tt, m, 0], c_out[tt, m, 1], c_out[tt, m, 2] = c0, c1, c2
            g0 = r00 * q0 + r01 * q1 + r02 * q2 + t0
            g1 = r10 * q0 + r11 * q1 + r12 * q2 + t1
            g2 = r20 * q0 + r21 * q1 + r22 * q2 + t2
            rigid_out[tt, m, 0], rigid_out[tt, m, 1], rigid_out[tt, m, 2] = g0, g1, g2
            rrbc_out[tt, m, 0] = g0 + r00 * c0 + r01 * c1 + r02 * c2
            rrbc_out[tt, m, 1] = g1 + r10 * c0 + r11 * c1 + r12 * c2
            rrbc_out[tt, m, 2] = g2 + r20 * c0 + r21 * c1 + r22 * c2


def ls_idw(reg_s, reg_b, fid_s, fid_b, query, k: int, power: float, exact_mm: float) -> dict:
    """Least squares + IDW for T trials: reg (T, Nr >= 3, 3), fid (T, Nf >= 1, 3), query (T, M, 3) (shapes
    checked by the caller; values may be anything: a trial with a non-finite input gives non-finite results
    and is flagged). Returns matrix (T,3,3), translation (T,3), fiducial_corrections (T,Nf,3), corrections
    (T,M,3), robot_rigid and robot_rrbc (T,M,3), mm; and for the caller's checks: finite (T, 5) bool per input
    (reg_s, reg_b, fid_s, fid_b, query), deviation (T, 2): the Frobenius distance (mm) of each trial's sensor
    and robot registration points from trial 0's, fiducial_mean (Nf,3) and query_mean (M,3) over trials."""
    arrays = [np.ascontiguousarray(x, dtype=float) for x in (reg_s, reg_b, fid_s, fid_b, query)]
    n_t, n_f, n_q = arrays[0].shape[0], arrays[2].shape[1], arrays[4].shape[1]
    out = {
        "matrix": np.empty((n_t, 3, 3)),
        "translation": np.empty((n_t, 3)),
        "fiducial_corrections": np.empty((n_t, n_f, 3)),
        "corrections": np.empty((n_t, n_q, 3)),
        "robot_rigid": np.empty((n_t, n_q, 3)),
        "robot_rrbc": np.empty((n_t, n_q, 3)),
        "finite": np.empty((n_t, 5), dtype=np.bool_),
        "deviation": np.empty((n_t, 2)),
        "fiducial_mean": np.empty((n_f, 3)),
        "query_mean": np.empty((n_q, 3)),
    }
    with np.errstate(all="ignore"):
        _ls_idw(
            *arrays,
            int(min(k, n_f)),
            float(power),
            float(exact_mm),
            out["matrix"],
            out["translation"],
            out["fiducial_corrections"],
            out["corrections"],
            out["robot_rigid"],
            out["robot_rrbc"],
            out["finite"],
            out["deviation"],
            out["fiducial_mean"],
            out["query_mean"],
        )
    out["fiducial_mean"] = out["fiducial_mean"] / n_t
    out["query_mean"] = out["query_mean"] / n_t
    return out
