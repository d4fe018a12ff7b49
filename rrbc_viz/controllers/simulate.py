"""The Monte Carlo tab (`MonteCarloController`): a run of the current setup in the background
(`montecarlo.MonteCarloRunner` over a snapshot of the session), after a setting changes, a drag ends or the seed
changes; Run again draws new noise; Stop ends a run under way."""

from __future__ import annotations

import copy
from typing import TYPE_CHECKING

import numpy as np

from ..montecarlo_runner import MonteCarloRunner

if TYPE_CHECKING:
    from ..context import AppContext


class MonteCarloController:
    """`actions.MonteCarloActions`: what it shows is in the app's state (`mc_trials`, `mc_plots`, `mc_draw`,
    `mc_seed`)."""

    def __init__(self, ctx: AppContext):
        self.ctx = ctx
        self.runner = MonteCarloRunner(self._mc_result, self._mc_started)

    def wait_idle(self, timeout: float) -> bool:
        return self.runner.wait_idle(timeout)

    def close(self) -> None:
        self.runner.stop()

    # ---------------------------------------------------------------------------------------- Monte Carlo
    def request(self, new_noise: bool = False, trials: int | None = None) -> bool:
        """Queue a Monte Carlo run of the current setup (scene mode); False when there is no error model.
        new_noise ("Run again"): a fresh noise seed, so the run differs from the last; otherwise the noise is
        seeded by the session's seed (the same setup gives the same plots)."""
        with self.ctx.lock:
            if trials is not None:
                self.ctx.state.mc_trials = int(trials)
            if self.ctx.session.kind != "scene":
                self.runner.cancel()
                self.ctx.controls.montecarlo.show_info(
                    "Monte Carlo needs a scene (an error model to simulate); measured data have none."
                )
                self.ctx.controls.show_monte_carlo_plots(False)
                return False
            snapshot = copy.copy(self.ctx.session)  # settings and layout are immutable values
            self.ctx.controls.show_monte_carlo_plots(True)
            seed = None
            if new_noise:
                self.ctx.state.mc_draw += 1
                seed = int(
                    np.random.default_rng([self.ctx.session.settings.seed, self.ctx.state.mc_draw]).integers(2**31 - 1)
                )
            self.ctx.state.mc_seed = seed
            self.runner.request(snapshot, self.ctx.state.mc_trials, seed)
            return True

    def stop(self) -> None:
        """The Stop button: forget the queued run and stop the one under way at its next chunk of trials; the
        plots keep the last finished run."""
        with self.ctx.lock:
            self.runner.cancel()
            self.ctx.controls.montecarlo.set_running(False)
            self.ctx.controls.montecarlo.show_info(
                "Monte Carlo: stopped (the plots show the last finished run, if any)."
            )

    def _mc_started(self) -> None:
        self.ctx.controls.montecarlo.set_running(True)
        self.ctx.controls.montecarlo.show_info("Monte Carlo: running…")

    def _mc_result(self, plots, error: str | None, seconds: float) -> None:
        c = self.ctx.controls
        c.montecarlo.set_running(False)
        if plots is None:
            c.montecarlo.show_info(f"Monte Carlo failed: {error}")
            return
        centres, rigid, rrbc = plots.histogram()
        dist, mean_rigid, mean_rrbc, half_rigid, half_rrbc = plots.by_distance()
        with self.ctx.lock, self.ctx.server.atomic():
            self.ctx.state.mc_plots = plots
            c.show_monte_carlo_plots(
                True,
                (centres, rigid, rrbc),
                (
                    dist,
                    mean_rigid,
                    mean_rrbc,
                    mean_rigid - half_rigid,
                    mean_rigid + half_rigid,
                    mean_rrbc - half_rrbc,
                    mean_rrbc + half_rrbc,
                ),
            )
            s = self.ctx.session.settings
            c.montecarlo.show_info(
                f"{plots.trials} trials × {plots.rigid.shape[1]} check points in the targets' "
                f"regions; {s.registration} + {s.interpolation}; noise ×{s.noise_scale:g}, "
                f"bias ×{s.bias_scale:g} ({seconds:.1f} s); "
                + (
                    f"noise draw {self.ctx.state.mc_draw} (**Run again** draws new noise). "
                    if self.ctx.state.mc_seed is not None
                    else "noise seeded by the session's seed (**Run again** draws new noise). "
                )
                + "Error vs distance: mean over the check points in each distance bin, with its 95 % interval. "
                "Updates after a setting changes, a drag ends or the seed changes."
            )
