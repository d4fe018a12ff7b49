"""The RRBC method a user chooses, as one value: the registration strategy and the interpolation, with their options.

The names come from one registry each — `registration.STRATEGIES` (with the options each strategy takes,
`registration.STRATEGY_OPTIONS`) and `interpolation.METHODS` — and everything that runs a method (`rrbc correct`,
the app's session, the Monte Carlo, the batch kernels) builds it from a `MethodOptions`, so a setting means the
same thing everywhere.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rrbc_core import interpolation, registration
from rrbc_core.errors import InputError

#: Strategies that draw random numbers and take a seed.
SEEDED = ("annealing", "clustering")


@dataclass(frozen=True)
class MethodOptions:
    """A registration strategy and an interpolation method with their options.

    Parameters
    ----------
    registration : str
        A name in `registration.STRATEGIES` ("least-squares", "three-point", "combinatorial", "annealing",
        "clustering").
    interpolation : str
        A name in `interpolation.METHODS` ("idw", "linear", "tps", "gp", "none").
    neighbors, power : int or None, float or None
        IDW only: the number of nearest fiducials k and the weight exponent p in 1/d^p (None: k = 4, p = 2).
    smoothing : float or None
        TPS only: scipy's RBF smoothing in the fiducials' local units (None: 0, exact interpolation).
    seed : int
        The seed of the strategies in `SEEDED`.
    interpolation_options : dict
        Further options of the interpolation method (gp: ``kernel``, ``noise_mm``).

    Invalid names or options raise `InputError` when the value is made.
    """

    registration: str = "least-squares"
    interpolation: str = "idw"
    neighbors: int | None = None
    power: float | None = None
    smoothing: float | None = None
    seed: int = 0
    interpolation_options: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.registration not in registration.STRATEGIES:
            raise InputError(
                f"unknown registration '{self.registration}': choose one of {', '.join(registration.STRATEGIES)}"
            )
        if self.interpolation not in interpolation.METHODS:
            raise InputError(
                f"unknown interpolation '{self.interpolation}': choose one of {', '.join(interpolation.METHODS)}"
            )
        if self.interpolation != "idw" and (self.neighbors is not None or self.power is not None):
            raise InputError("--neighbors and --power apply to --interpolation idw only")
        if self.interpolation != "tps" and self.smoothing is not None:
            raise InputError("smoothing applies to --interpolation tps only")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)):
            raise InputError(f"seed must be an integer, got {self.seed!r}")
        object.__setattr__(self, "interpolation_options", dict(self.interpolation_options))
        self.interpolator()  # validates the interpolation's options

    def interpolation_kwargs(self) -> dict:
        """The options handed to `interpolation.make_interpolator` for this method (defaults left out)."""
        opts = dict(self.interpolation_options)
        if self.neighbors is not None:
            opts["k"] = self.neighbors
        if self.power is not None:
            opts["power"] = self.power
        if self.smoothing is not None:
            opts["smoothing"] = self.smoothing
        return opts

    def interpolator(self):
        """The interpolation method object (e.g. `interpolation.IDW(k, power)`), ready to `fit`."""
        return interpolation.make_interpolator(self.interpolation, **self.interpolation_kwargs())

    def registration_options(self) -> dict:
        """The options of the registration strategy: ``{"seed": seed}`` for the seeded ones, else ``{}``."""
        return {"seed": int(self.seed)} if self.registration in SEEDED else {}

    def register(self, sensor, robot) -> registration.Registration:
        """Register paired points, sensor (N, 3) sensor frame and robot (N, 3) robot frame, mm."""
        return registration.register(self.registration, sensor, robot, **self.registration_options())

    def interpolation_json(self) -> dict:
        """The ``interpolation`` object of `rrbc correct --json`: the method and, for idw, k and p in force."""
        out = {"method": self.interpolation}
        if self.interpolation == "idw":
            method = self.interpolator()
            out["neighbors"], out["power"] = method.k, method.power
        out.update(self.interpolation_options)
        if self.smoothing is not None:
            out["smoothing"] = self.smoothing
        return out
