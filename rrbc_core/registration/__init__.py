"""Registration: from paired sensor/robot points to the sensor→robot mapping (`robot = mapping.apply(sensor)`).

`register(name, sensor, robot, **options)` runs a strategy by its command-line name (`STRATEGIES`); each strategy
is also callable by itself. The strategies, the mappings they return and the checks they make are described in
`strategies.py`.
"""

from rrbc_core.registration.strategies import (
    MAX_SUBSET_POINTS,
    STRATEGIES,
    STRATEGY_OPTIONS,
    LinearMap,
    PiecewiseMap,
    Registration,
    annealing,
    check_subset_count,
    clustering,
    combinatorial,
    kabsch,
    kmeans,
    least_squares,
    register,
    three_point,
    three_point_matrices,
)

__all__ = [
    "MAX_SUBSET_POINTS",
    "STRATEGIES",
    "STRATEGY_OPTIONS",
    "LinearMap",
    "PiecewiseMap",
    "Registration",
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
