"""`rrbc reproduce crpi`: what NIST's point-level breadboard readings hold, and which error model they support.

`run` puts together the model-free facts (`crpi`) and the candidate models (`crpi_models`): every model is fitted
to the residuals, scored, and simulated on this exact layout to predict the rigid residual RMS, the variogram and
the RRBC change of the leave-one-site-out experiment; the supported model is named and its prediction set against
what was measured. `Study.to_json()` is the JSON of `rrbc reproduce crpi --json` (docs/cli.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rrbc_core.errors import InputError
from rrbc_core.studies import crpi, crpi_joint, crpi_models

DEFAULT_REPLICATES = 1000
DEFAULT_JOINT_REPLICATES = 100
SMOOTH = f"{crpi_models.SMOOTH_LENGTHS_MM[0]:.0f}-{crpi_models.SMOOTH_LENGTHS_MM[-1]:.0f}"
MAX_REPLICATES = 100_000


@dataclass(frozen=True)
class Study:
    sites: crpi.Sites
    repeatability_mm: tuple
    rigid_residuals_mm: np.ndarray  # (S, 3) robot frame
    rigid_rms_mm: float  # RMS of |r_i| over the sites
    variogram: crpi.Variogram
    loso: dict  # method -> (rigid errors (S,), rrbc errors (S,))
    scores: dict  # name -> crpi_models.Score
    predictions: dict  # name -> crpi_models.Prediction
    chosen: str
    replicates: int
    seed: int
    joint: dict | None = None  # crpi_joint.to_json, None when skipped

    @property
    def measured_change(self) -> float:
        rig, rr = self.loso["idw"]
        return crpi.rms(rr) / crpi.rms(rig) - 1.0

    def cause(self) -> str:
        sc = self.scores[self.chosen]
        pr = self.predictions[self.chosen]
        kin = self.predictions["kinematic"].rrbc_change
        spacing = float(min(crpi.pair_distances(self.sites.truth)[2]))
        sizes = ", ".join(f"{k} {v:.3g}" for k, v in sc.sizes.items()) or "none"
        rep_mean = float(np.sqrt(np.sum(np.square(self.repeatability_mm)) / np.mean(self.sites.counts)))
        lo, hi = pr.rrbc_change[1], pr.rrbc_change[2]
        inside = lo <= self.measured_change <= hi
        text = (
            f"The data support '{self.chosen}' ({sc.cause}; fitted size: {sizes}). After a rigid fit the ten site "
            f"means leave {self.rigid_rms_mm:.2f} mm RMS of residual, where the repeated seatings alone would leave "
            f"about {rep_mean:.2f} mm (the noise of a mean of {int(np.mean(self.sites.counts))} readings), and the "
            f"residuals of sites {spacing:.0f} mm or more apart show no correlation these data can detect: the "
            f"variogram is flat ({', '.join(f'{g:.2f}' for g in self.variogram.gamma_mm2)} mm² from near to far "
            f"pairs) and no smooth field of length {SMOOTH} mm is significant beside per-site offsets. An error that "
            f"does not carry from one site to the next cannot be interpolated from neighbouring fiducials: leaving "
            f"one site out, RRBC (IDW k = 4, p = 2) changed the RMS error by {100 * self.measured_change:+.1f} %; "
            f"the supported model predicts {100 * pr.rrbc_change[0]:+.1f} % (95 % of simulated experiments "
            f"{100 * lo:+.1f} to {100 * hi:+.1f} %){', the measurement inside' if inside else ', the measurement OUTSIDE'}"
            f". A UR5 kinematic field fitted to the same points predicts {100 * kin[0]:+.1f} % "
            f"({100 * kin[1]:+.1f} to {100 * kin[2]:+.1f} %) and is rejected by the points' likelihood "
            f"(REML {self.scores['kinematic'].reml:.1f} against {sc.reml:.1f})."
        )
        if self.joint is not None:
            m = self.joint["models"]
            ch = m[self.joint["chosen"]]
            other = [k for k in m if k != self.joint["chosen"]][0]
            kin_tables = m["kinematic"]["tables_only"]["rrbc_change"]
            t_best = min(m, key=lambda k: m[k]["tables_only"]["deviance_tables"])
            text += (
                f" The Van Wyk tables alone prefer '{t_best}' (their misfit "
                f"{m[t_best]['tables_only']['deviance_tables']:.1f} against "
                f"{min(v['tables_only']['deviance_tables'] for k, v in m.items() if k != t_best):.1f}), but fitted "
                f"jointly with the points (layout A) '{self.joint['chosen']}' explains both better than '{other}' "
                f"(joint misfit {ch['joint']['deviance']:.1f} against {m[other]['joint']['deviance']:.1f}), at "
                f"{', '.join(f'{k} {v:.3g}' for k, v in ch['joint']['params'].items())}; there RRBC on the plate "
                f"changes the error by {100 * ch['joint']['rrbc_change']:+.0f} %, where the kinematic model fitted to "
                f"the tables alone predicted {100 * kin_tables:+.0f} %. The two data sets are in tension: at the "
                f"joint fit the tables' misfit is {ch['joint']['deviance_tables']:.1f}, and they pull the noise apart "
                f"(the points' repeated seatings scatter {ch['points_only']['params']['sigma_mm']:.3f} mm, the tables "
                f"alone want {ch['tables_only']['params']['sigma_mm']:.3f} mm), so they may not come from one session."
            )
        return text

    def to_json(self) -> dict:
        pr = self.predictions[self.chosen]
        return {
            "data": {"source": crpi.CITATION, "sites": len(self.sites.truth), "readings": int(self.sites.counts.sum())},
            "repeatability_mm": list(self.repeatability_mm),
            "rigid_residual_rms_mm": self.rigid_rms_mm,
            "sites": [
                {"truth_mm": t.tolist(), "readings": int(n), "residual_mm": r.tolist()}
                for t, n, r in zip(self.sites.truth, self.sites.counts, self.rigid_residuals_mm)
            ],
            "variogram": self.variogram.to_json(),
            "loso": {
                m: {"rmst_rigid_mm": crpi.rms(a), "rmst_rrbc_mm": crpi.rms(b), "change": crpi.rms(b) / crpi.rms(a) - 1}
                for m, (a, b) in self.loso.items()
            },
            "models": [
                {
                    "name": sc.name,
                    "cause": sc.cause,
                    "sizes": sc.sizes,
                    "parameters": crpi_models.n_params(crpi_models.candidate_by_name(sc.name)),
                    "reml": sc.reml,
                    "aic": sc.aic,
                    "cv_log_density": sc.cv_log_density,
                    "cv_rms_mm": sc.cv_rms_mm,
                    "predictions": self.predictions[sc.name].to_json(),
                }
                for sc in self.scores.values()
            ],
            "chosen": self.chosen,
            "selection": (
                "nested likelihood-ratio tests of the restricted likelihood at a family-wise "
                f"{crpi_models.FAMILY_ALPHA:g}: per-site offsets against repeatability alone, then each extension "
                "(smooth field at each length, kinematic, flatness, scale) beside the offsets; the offsets kept beside "
                "a found extension only if still significant"
            ),
            "predicted_rrbc_change": {"mean": pr.rrbc_change[0], "lo95": pr.rrbc_change[1], "hi95": pr.rrbc_change[2]},
            "measured_rrbc_change": self.measured_change,
            "cause": self.cause(),
            "joint_fit": self.joint,
            "joint_fit_status": "computed" if self.joint is not None else "skipped (--joint-replicates 0)",
            "replicates": self.replicates,
            "seed": self.seed,
        }


def run(
    replicates: int = DEFAULT_REPLICATES,
    seed: int = 0,
    sites: crpi.Sites | None = None,
    joint_replicates: int = DEFAULT_JOINT_REPLICATES,
    scheduler: str | None = None,
    progress_factory=None,
) -> Study:
    """The whole study on the shipped data (or `sites`). `replicates` simulated experiments per model;
    `joint_replicates` per direction for the joint fit with the Van Wyk tables (`crpi_joint`; 0 skips it).
    The candidates' simulations and the joint fits are tasks of `runtime.tasks` (`scheduler`), each with its own
    seed: the same numbers wherever they run. `progress_factory(total)` -> an object with update(n) and
    close() (a progress bar), advanced as they finish."""
    if not (10 <= int(replicates) <= MAX_REPLICATES):
        raise InputError(f"--replicates must be from 10 to {MAX_REPLICATES}, got {replicates}")
    if not (int(joint_replicates) == 0 or 20 <= int(joint_replicates) <= 2000):
        raise InputError(f"--joint-replicates must be 0 (skip) or from 20 to 2000, got {joint_replicates}")
    from rrbc_core.runtime.tasks import task_runner

    sites = crpi.load() if sites is None else sites
    _, resid = crpi.rigid_fit(sites.truth, sites.means)
    loso = {m: crpi.loso(sites.truth, sites.means, m, **o) for m, o in crpi.LOSO_METHODS.items()}
    lay = crpi_models.layout_of(sites)
    scores = {c.name: crpi_models.score(sites, c, lay) for c in crpi_models.CANDIDATES}
    sims = [(sites, c, scores[c.name].sizes, int(replicates), seed + k) for k, c in enumerate(crpi_models.CANDIDATES)]
    joints = crpi_joint.tasks(joint_replicates, seed, sites) if joint_replicates else []
    bar = progress_factory(len(sims) + len(joints)) if progress_factory else None
    tick = None if bar is None else bar.update
    try:
        with task_runner(scheduler) as run_all:
            predicted = run_all(_simulate_task, sims, tick)
            joint = run_all(crpi_joint.fit_task, joints, tick)
    finally:
        if bar is not None:
            bar.close()
    return Study(
        sites,
        tuple(float(v) for v in crpi.repeatability(sites)),
        resid,
        crpi.rms(np.linalg.norm(resid, axis=1)),
        crpi.variogram(sites.truth, resid),
        loso,
        scores,
        {c.name: p for c, p in zip(crpi_models.CANDIDATES, predicted)},
        crpi_models.select(list(scores.values())),
        int(replicates),
        int(seed),
        crpi_joint.to_json(joint, joint_replicates) if joint_replicates else None,
    )


def _simulate_task(task: tuple):
    """One candidate's simulated predictions (a task of `runtime.tasks`, seeded by its own seed)."""
    return crpi_models.simulate(*task)
