"""The RRBC method a user chooses, as one value: a registration strategy object and an interpolation method object.

`MethodOptions(registration, interpolation)` holds the two configured objects — `registration.LeastSquares()`, …,
`interpolation.IDW(k=4, power=2)`, … — whose fields are their options, each stated once with its flag, bounds and
help (`option_specs`). Everything that runs a method (`rrbc correct`, the app's session, the Monte Carlo, the batch
kernels) takes a `MethodOptions`; everything that offers one (the command's flags, the app's widgets, the session's
settings) is derived from the option fields through `method_flags` and `MethodOptions.named`, so a setting has one
spelling and means the same thing everywhere.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Any

from rrbc_core import interpolation, registration
from rrbc_core.errors import InputError
from rrbc_core.option_specs import OptionSpec, option_specs

__all__ = ["SEEDED", "MethodOptions", "method_flags"]

#: Strategies that draw random numbers and take a seed.
SEEDED = tuple(name for name, cls in registration.STRATEGIES.items() if cls.seeded)


@functools.cache
def method_flags() -> dict[str, list[tuple[str, str, OptionSpec]]]:
    """Every option of every method by its flag: flag -> [(side, method name, spec), …], side "registration" or
    "interpolation". The command line makes one `--flag` per entry; an option of the chosen method is routed to it by
    its flag (`MethodOptions.named`). Built once (the registries are fixed): read it, do not change it."""
    out: dict[str, list] = {}
    for side, registry in (("registration", registration.STRATEGIES), ("interpolation", interpolation.METHODS)):
        for name, cls in registry.items():
            for spec in option_specs(cls):
                out.setdefault(spec.flag, []).append((side, name, spec))
    return out


def _build(side: str, name: str, seed: int | None, given: dict):
    """The option object of `name` on `side` from flag-named options (those it does not take are ignored here)."""
    registry = registration.STRATEGIES if side == "registration" else interpolation.METHODS
    key = str(name).strip().lower()
    if key not in registry:
        raise InputError(f"unknown {side} '{name}': choose one of {', '.join(registry)}")
    cls = registry[key]
    kwargs = {}
    for spec in option_specs(cls):
        if spec.flag in given and given[spec.flag] is not None:
            kwargs[spec.name] = given[spec.flag]
        elif spec.name == "seed" and seed is not None:
            kwargs["seed"] = seed
    return (
        registration.make_strategy(key, **kwargs)
        if side == "registration"
        else interpolation.make_interpolator(key, **kwargs)
    )


@dataclass(frozen=True)
class MethodOptions:
    """A registration strategy and an interpolation method, each a configured option object.

    Parameters
    ----------
    registration : strategy object or str
        `registration.LeastSquares()`, `Combinatorial(average=…)`, `Annealing(seed=…)`, …, or a name in
        `registration.STRATEGIES` (its defaults).
    interpolation : method object or str
        `interpolation.IDW(k, power)`, `TPS(smoothing)`, `GP(kernel, noise_mm)`, `Linear()`, `NoCorrection()`, or a
        name in `interpolation.METHODS` (its defaults).

    Build one from command-line style names and flag-named options with `MethodOptions.named(...)`. Invalid names
    or options raise `InputError` when the value is made.
    """

    registration: Any = field(default_factory=registration.LeastSquares)
    interpolation: Any = field(default_factory=interpolation.IDW)

    def __post_init__(self):
        if isinstance(self.registration, str):
            object.__setattr__(self, "registration", registration.make_strategy(self.registration))
        if isinstance(self.interpolation, str):
            object.__setattr__(self, "interpolation", interpolation.make_interpolator(self.interpolation))
        if type(self.registration) not in registration.STRATEGIES.values():
            raise InputError(f"not a registration strategy: {self.registration!r}")
        if type(self.interpolation) not in interpolation.METHODS.values():
            raise InputError(f"not an interpolation method: {self.interpolation!r}")

    @classmethod
    def named(
        cls, registration: str = "least-squares", interpolation: str = "idw", seed: int | None = None, **options
    ) -> MethodOptions:
        """The method from names and options keyed by their flags (as the command line and the session's settings
        give them: ``neighbors``, ``power``, ``smoothing``, ``kernel``, ``noise-mm``, ``average``, ``clusters``, …;
        None: the default). `seed` goes to a seeded strategy. An option that neither chosen method takes is
        refused, naming the methods it belongs to."""
        flags = method_flags()
        given = {k.replace("_", "-") if k.replace("_", "-") in flags else k: v for k, v in options.items()}
        reg = _build("registration", registration, seed, given)
        interp = _build("interpolation", interpolation, None, given)
        chosen = {registration.strip().lower(), interpolation.strip().lower()}
        for flag, value in given.items():
            if value is None:
                continue
            owners = flags.get(flag)
            if owners is None:
                raise InputError(f"unknown method option '{flag}'")
            if not any(name in chosen for _, name, _ in owners):
                names = sorted({name for _, name, _ in owners})
                raise InputError(f"--{flag} applies to {' and '.join(names)} only")
        return cls(reg, interp)

    # ------------------------------------------------------------------------------------------------ reading
    @property
    def registration_name(self) -> str:
        return self.registration.name

    @property
    def interpolation_name(self) -> str:
        return self.interpolation.name

    @property
    def seed(self) -> int | None:
        """The seeded strategy's seed (None for an unseeded one)."""
        return getattr(self.registration, "seed", None)

    def option_values(self) -> dict[str, Any]:
        """Every option of both methods by its flag (the session's settings read them here)."""
        out = {}
        for obj in (self.registration, self.interpolation):
            for spec in option_specs(obj):
                out[spec.flag] = getattr(obj, spec.name)
        return out

    # ----------------------------------------------------------------------------------------------- running
    def interpolator(self):
        """The interpolation method object (e.g. `interpolation.IDW(k, power)`), ready to `fit`."""
        return self.interpolation

    def interpolation_kwargs(self) -> dict:
        """The interpolation's options by field name (what `interpolation.make_interpolator` and the batch kernels
        take)."""
        return {s.name: getattr(self.interpolation, s.name) for s in option_specs(self.interpolation)}

    def register(self, sensor, robot) -> registration.Registration:
        """Register paired points, sensor (N, 3) sensor frame and robot (N, 3) robot frame, mm."""
        return self.registration.register(sensor, robot)

    # ------------------------------------------------------------------------------------------------ showing
    def interpolation_json(self) -> dict:
        """The ``interpolation`` object of `rrbc correct --json`: the method and its options (idw: ``neighbors``,
        ``power``)."""
        out: dict = {"method": self.interpolation_name}
        for spec in option_specs(self.interpolation):
            out[spec.flag.replace("-", "_")] = getattr(self.interpolation, spec.name)
        return out

    def registration_json(self) -> dict:
        """The strategy's options by flag (JSON keys), besides its name."""
        return {s.flag.replace("-", "_"): getattr(self.registration, s.name) for s in option_specs(self.registration)}

    def describe(self) -> str:
        """One line: "least-squares + idw (k=4, p=2)" style, for panels and reports."""
        opts = ", ".join(
            f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
            for k, v in self.interpolation_json().items()
            if k != "method"
        )
        return f"{self.registration_name} + {self.interpolation_name}" + (f" ({opts})" if opts else "")
