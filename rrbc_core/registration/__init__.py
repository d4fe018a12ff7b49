"""Registration: from paired sensor/robot points to the sensor→robot mapping (`robot = mapping.apply(sensor)`).

Each strategy is a frozen option object (`LeastSquares`, `ThreePoint`, `Combinatorial`, `Annealing`, `Clustering`;
`options.py`) with `.register(sensor, robot)`; `make_strategy(name, **options)` builds one from its command-line
name (`STRATEGIES`, the one registry) and `register(name, sensor, robot, **options)` runs it. The numerics, the
mappings they return (typed by the `SensorToRobot` protocol) and the checks they make are in `strategies.py`.
"""

from rrbc_core.registration.options import (
    STRATEGIES,
    STRATEGY_OPTIONS,
    Annealing,
    Clustering,
    Combinatorial,
    LeastSquares,
    Strategy,
    ThreePoint,
    make_strategy,
    register,
)
from rrbc_core.registration.strategies import (
    MAX_SUBSET_POINTS,
    LinearMap,
    PiecewiseMap,
    Registration,
    SensorToRobot,
    annealing,
    check_subset_count,
    clustering,
    combinatorial,
    kabsch,
    kmeans,
    least_squares,
    three_point,
    three_point_matrices,
)

__all__ = [
    "Annealing",
    "Clustering",
    "Combinatorial",
    "LeastSquares",
    "Strategy",
    "ThreePoint",
    "make_strategy",
    "MAX_SUBSET_POINTS",
    "STRATEGIES",
    "STRATEGY_OPTIONS",
    "LinearMap",
    "PiecewiseMap",
    "Registration",
    "SensorToRobot",
    "annealing",
    "check_subset_count",
    "clustering",
    "combinatorial",
    "kabsch",
    "kmeans",
    "least_squares",
    "register",
    "three_point",
    "three_point_matrices",
]
