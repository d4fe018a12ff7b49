"""Compiled simulated-annealing chain (Van Wyk & Marvel 2018, eqs. 8-15), one chain per call.

`batch.annealing_batch` runs thousands of independent chains of 5000 steps each (`rrbc reproduce vanwyk2018` runs
about a quarter of a million). A chain is sequential — each step depends on the previous acceptance — so numpy can
only advance many chains in lockstep, paying ~30 array operations per step; `benchmarks/run.py`
(`mc_throughput_annealing`) and `benchmarks/reproduce_speed.py` measure what compiling it (numba, made for numeric
loops) gains.

Per step, the same decisions as the core (`registration.annealing`): candidate Θ' = Θ + step (6 numbers added in
the same order), modifier R = Rz(α) Ry(β) Rx(γ) with each entry formed as the product of the three 3x3 matrices
forms it (the zero terms are exact), cost Σ‖r − (R m + t)‖² (mm², or the caller's units), accepted if
Δ < 0 or u < exp(−Δ / T_τ), T_τ = 1 / (C ln τ), τ = step + 2; the best Θ seen (first strict improvement) is
returned. The proposals and uniforms are drawn by the caller from the chain's own numpy generator, in the core's
order, so a chain's result does not depend on where or with which others it runs. Costs may differ from the core's
in the last bit (the sum's order); `tests/simulation/test_batch.py` holds the results to the core's.

Import lazily (it imports numba); the machine code is cached beside this file.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _cost(m, r, th):  # pragma: no cover - compiled; tested through annealing_batch
    """Σ‖r − (R(θ) m + θ[:3])‖² for points m, r (n, 3)."""
    ca, sa = math.cos(th[3]), math.sin(th[3])
    cb, sb = math.cos(th[4]), math.sin(th[4])
    cg, sg = math.cos(th[5]), math.sin(th[5])
    casb, sasb = ca * sb, sa * sb
    r00, r01, r02 = ca * cb, casb * sg - sa * cg, casb * cg + sa * sg
    r10, r11, r12 = sa * cb, sasb * sg + ca * cg, sasb * cg - ca * sg
    r20, r21, r22 = -sb, cb * sg, cb * cg
    tot = 0.0
    for p in range(m.shape[0]):
        x, y, z = m[p, 0], m[p, 1], m[p, 2]
        e0 = r[p, 0] - ((x * r00 + y * r01 + z * r02) + th[0])
        e1 = r[p, 1] - ((x * r10 + y * r11 + z * r12) + th[1])
        e2 = r[p, 2] - ((x * r20 + y * r21 + z * r22) + th[2])
        tot += e0 * e0 + e1 * e1 + e2 * e2
    return tot


@njit(cache=True, nogil=True)
def anneal_chain(mapped, robot, steps, uniforms, cooling_c):  # pragma: no cover - compiled
    """Best modifier Θ (6,) (x, y, z, α, β, γ) of one chain.

    mapped, robot: (n, 3) the initially registered sensor points and their robot readings; steps: (I, 6)
    proposal steps (normals times step sizes); uniforms: (I,) acceptance draws; cooling_c: C."""
    theta = np.zeros(6)
    cand = np.zeros(6)
    best = np.zeros(6)
    c_cur = _cost(mapped, robot, theta)
    c_best = c_cur
    for j in range(steps.shape[0]):
        temp = 1.0 / (cooling_c * math.log(j + 2))
        for i in range(6):
            cand[i] = theta[i] + steps[j, i]
        c_new = _cost(mapped, robot, cand)
        delta = c_new - c_cur
        if delta < 0 or uniforms[j] < math.exp(-delta / temp):
            theta[:] = cand
            c_cur = c_new
            if c_cur < c_best:
                best[:] = theta
                c_best = c_cur
    return best
