"""The registration strategies as option objects, one registry of their names (`STRATEGIES`), and `register`.

Each strategy is a small frozen dataclass holding its options (fields made with `option_specs.option`: flag, label,
bounds, help, stated once) with `.register(sensor, robot) -> Registration` — configured estimation objects, as
Open3D passes them, and the same shape as the interpolation methods (`interpolation.IDW`, …). `make_strategy(name,
**options)` builds one from its command-line name; `register(name, sensor, robot, **options)` runs it. The numerics
are the functions of `strategies.py`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

from numpy.typing import ArrayLike

from rrbc_core.geometry import points as geometry
from rrbc_core.option_specs import build_from_registry, check_options, option, option_specs
from rrbc_core.registration.strategies import (
    Registration,
    annealing,
    clustering,
    combinatorial,
    least_squares,
    three_point,
)
from rrbc_core.runtime.threads import thread_limited

__all__ = [
    "STRATEGIES",
    "STRATEGY_OPTIONS",
    "Annealing",
    "Clustering",
    "Combinatorial",
    "LeastSquares",
    "ThreePoint",
    "make_strategy",
    "register",
]


def _average() -> Any:
    return option(
        "elementwise",
        label="Averaging",
        help="combinatorial and clustering: average the 3-point registrations element by element (as published) or by "
        "the chordal mean of their rotations",
        choices=("elementwise", "chordal"),
    )


def _seed() -> Any:
    return option(0, label="Seed", help="seed of annealing and clustering (default 0)", bounds=(-(2**63), 2**63 - 1))


class StrategyObject(Protocol):
    """What every strategy class offers: its name, whether it is seeded, the per-call data it accepts, and
    `register`."""

    name: ClassVar[str]
    seeded: ClassVar[bool]
    extras: ClassVar[tuple]

    def register(self, p_sensor: ArrayLike, b_robot: ArrayLike) -> Registration: ...


@dataclass(frozen=True)
class LeastSquares:
    """Least-squares rigid fit (Arun/Horn/Umeyama; `strategies.least_squares`)."""

    name: ClassVar[str] = "least-squares"
    seeded: ClassVar[bool] = False
    extras: ClassVar[tuple] = ("weights",)  # data passed per call, not an option

    def register(self, p_sensor: ArrayLike, b_robot: ArrayLike, weights: ArrayLike | None = None) -> Registration:
        return least_squares(p_sensor, b_robot, weights=weights)


@dataclass(frozen=True)
class ThreePoint:
    """The frame of three points in each space (Van Wyk & Marvel eqs. 1–5; `strategies.three_point`)."""

    name: ClassVar[str] = "three-point"
    seeded: ClassVar[bool] = False
    extras: ClassVar[tuple] = ()

    def register(self, p_sensor: ArrayLike, b_robot: ArrayLike) -> Registration:
        return three_point(p_sensor, b_robot)


@dataclass(frozen=True)
class Combinatorial:
    """The average of every non-degenerate 3-point subset's registration (`strategies.combinatorial`)."""

    name: ClassVar[str] = "combinatorial"
    seeded: ClassVar[bool] = False
    extras: ClassVar[tuple] = ()
    average: str = _average()
    degeneracy_ratio: float = option(
        geometry.SUBSET_DEGENERACY_RATIO,
        flag="degeneracy-ratio",
        label="Subset degeneracy ratio",
        help="combinatorial: subsets whose spread ratio sigma2/sigma1 is below this are left out (default 0.05)",
        bounds=(0.0, 1.0),
        lo_open=True,
    )

    def __post_init__(self):
        check_options(self, "combinatorial")

    def register(self, p_sensor: ArrayLike, b_robot: ArrayLike) -> Registration:
        return combinatorial(p_sensor, b_robot, average=self.average, degeneracy_ratio=self.degeneracy_ratio)


@dataclass(frozen=True)
class Annealing:
    """Simulated-annealing refinement of the combinatorial registration (eqs. 8–15; `strategies.annealing`)."""

    name: ClassVar[str] = "annealing"
    seeded: ClassVar[bool] = True
    extras: ClassVar[tuple] = ()
    seed: int = _seed()
    iterations: int = option(
        5000, label="Annealing iterations", help="annealing: steps of the chain (default 5000)", bounds=(1, 1_000_000)
    )
    cooling_c: float = option(
        2.0,
        flag="cooling-c",
        label="Annealing cooling C",
        help="annealing: C in the temperature 1/(C ln tau) (default 2)",
        bounds=(0.0, 1e3),
        lo_open=True,
    )

    def __post_init__(self):
        check_options(self, "annealing")

    def register(self, p_sensor: ArrayLike, b_robot: ArrayLike, initial: Registration | None = None) -> Registration:
        return annealing(
            p_sensor, b_robot, initial=initial, seed=self.seed, iterations=self.iterations, cooling_c=self.cooling_c
        )


@dataclass(frozen=True)
class Clustering:
    """Piecewise registration over k-means clusters of the registration points (`strategies.clustering`)."""

    name: ClassVar[str] = "clustering"
    seeded: ClassVar[bool] = True
    extras: ClassVar[tuple] = ()
    clusters: int = option(
        2, label="Clusters", help="clustering: number of clusters (default 2)", bounds=(1, 50), ui=(1, 8, 1)
    )
    seed: int = _seed()
    average: str = _average()

    def __post_init__(self):
        check_options(self, "clustering")

    def register(self, p_sensor: ArrayLike, b_robot: ArrayLike) -> Registration:
        return clustering(p_sensor, b_robot, clusters=self.clusters, seed=self.seed, average=self.average)


Strategy = LeastSquares | ThreePoint | Combinatorial | Annealing | Clustering

#: The registry of registration strategies: command-line name -> option class.
STRATEGIES: dict[str, type[StrategyObject]] = {
    c.name: c for c in (LeastSquares, ThreePoint, Combinatorial, Annealing, Clustering)
}

#: The options each strategy takes by name besides its seed, in `register` and in the batch kernels
#: (`simulation.batch.rrbc_batch`): its option fields and the per-call data it accepts (least squares' weights).
STRATEGY_OPTIONS: dict[str, tuple] = {
    name: tuple(s.name for s in option_specs(cls) if s.name != "seed") + cls.extras for name, cls in STRATEGIES.items()
}


def make_strategy(name: str, **options) -> StrategyObject:
    """The strategy object for a command-line name with its options (None: the default). InputError for an unknown
    name or an option the strategy does not take or that is out of range."""
    return build_from_registry(
        STRATEGIES,
        name,
        options,
        f"unknown registration '{name}': choose one of {', '.join(STRATEGIES)}",
        "registration {key}",
    )


@thread_limited
def register(method: str, sensor: ArrayLike, robot: ArrayLike, **options) -> Registration:
    """Register paired points with a named strategy: the sensor→robot mapping and its residuals.

    Parameters
    ----------
    method : str
        A name in `STRATEGIES`: "least-squares", "three-point", "combinatorial", "annealing", "clustering".
    sensor, robot : (N, 3) array_like
        The same N physical points measured in the sensor frame and in the robot frame, mm (`p_sensor`, `b_robot`
        in the strategies; the public call keeps its published names).
    **options
        The strategy's options (its fields, e.g. ``seed`` for annealing and clustering) and per-call data
        (least squares' ``weights``, annealing's ``initial`` registration).

    Returns
    -------
    Registration
        ``mapping`` (robot = mapping.apply(sensor)), ``residuals`` (N, 3) robot frame, mm, and ``fre_rms_mm``.

    Raises
    ------
    InputError
        An unknown name or option, fewer than 3 points, coincident or (nearly) collinear points.
    """
    cls = STRATEGIES.get(str(method).strip().lower())
    call = {}
    for extra in ("weights", "initial"):
        if extra in options and cls is not None and (extra in cls.extras or extra == "initial" and cls is Annealing):
            call[extra] = options.pop(extra)
    return make_strategy(method, **options).register(sensor, robot, **call)
