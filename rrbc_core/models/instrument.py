"""The instrument model: how noisy one reading of a point is, for the per-point bounds (`correction.bounds`).

A reading's noise is a covariance (3, 3) in the frame it is read in (mm²). Two kinds of instrument:

* *cartesian* (stereo cameras, a CMM): the same standard deviation σ on each axis, C = σ² I;
* *polar* (laser tracker, total station): a distance and two angles from the instrument, which stands at the sensor
  frame's origin. At a point p at range r along unit direction u:

      σ_d(r) = distance_mm + distance_ppm·10⁻⁶·r          (along u)
      σ_t(r)² = floor_mm² + (angle_urad·10⁻⁶·r)²           (across u, both directions)
      C(p) = σ_d² u uᵀ + σ_t² (I − u uᵀ)

The robot's reading of a point (where its controller says the tool is; where it goes when sent there) has its own
per-axis σ, `robot_mm` (its repeatability). The presets' figures are makers' published specifications read as in
docs/uncertainty.md (a maximum permissible error taken as two standard deviations); every figure can be given
instead (`with_overrides`), and without an instrument the noise is estimated from the data
(`correction.bound_inputs.estimate_noise`). Units mm, µrad, ppm.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from rrbc_core.errors import InputError

#: instrument name -> its preset (docs/uncertainty.md, "Instruments")
PRESETS: dict[str, dict] = {
    "tracker": {"polar": True, "distance_mm": 0.008, "distance_ppm": 0.4, "angle_urad": 2.5, "floor_mm": 0.005},
    "total-station": {"polar": True, "distance_mm": 1.0, "distance_ppm": 1.5, "angle_urad": 4.85, "floor_mm": 0.0},
    "stereo": {"polar": False, "sigma_mm": 0.07},
    "cmm": {"polar": False, "sigma_mm": 0.001},
}
INSTRUMENTS = tuple(PRESETS)
#: the largest scale error (ppm) each instrument plausibly has (`rrbc diagnose`'s plausibility limits; docs/limits.md,
#: "What a sensor can plausibly have"): a tracker's or a CMM's distances are good to a few ppm once compensated for
#: temperature (about 1 ppm per kelvin of air for a tracker, 11.5 ppm per kelvin of a steel scale left
#: uncompensated); a total station's to 1.5 ppm plus its atmospheric correction (1 ppm per kelvin or per 3.6 hPa
#: left out); a stereo camera's scale rests on its calibrated baseline, often a tenth of a per cent off
PLAUSIBLE_SCALE_PPM: dict[str, float] = {"tracker": 10.0, "total-station": 20.0, "stereo": 5000.0, "cmm": 15.0}
#: an override larger than this (mm, or µrad for angles) is refused: it is not a measuring instrument's noise
MAX_SIGMA_MM = 100.0
MAX_ANGLE_URAD = 1e5


@dataclass(frozen=True)
class Instrument:
    """One instrument's reading noise (module docstring), the robot's, and where the figures came from.

    Attributes
    ----------
    name : str
        A preset's name, ``given`` (figures given without a preset) or ``estimated`` (from the data).
    polar : bool
        Distance-and-angle noise about the sensor frame's origin (True) or per-axis (False).
    sigma_mm : float
        Cartesian: the per-axis σ of a sensor reading, mm.
    distance_mm, distance_ppm, angle_urad, floor_mm : float
        Polar: the distance σ (mm plus ppm of the range), the angle σ (µrad) and the transverse floor (mm).
    robot_mm : float or None
        The robot's per-axis σ, mm (None: not known yet, estimated from the data).
    source : str
        Where the sensor's figures came from, in words (a preset, given, estimated from repeats ...).
    robot_source : str
        Where the robot's came from.
    """

    name: str
    polar: bool = False
    sigma_mm: float = 0.0
    distance_mm: float = 0.0
    distance_ppm: float = 0.0
    angle_urad: float = 0.0
    floor_mm: float = 0.0
    robot_mm: float | None = None
    source: str = ""
    robot_source: str = ""
    #: a model's own noise instead of the figures: p_sensor (N, 3) -> (sensor (N, 3, 3) sensor frame, robot
    #: (N, 3, 3) robot frame) covariances, mm² (a scene's error model: `scene_instrument`)
    covariances: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None = field(default=None, compare=False)

    def sensor_cov(self, p_sensor) -> np.ndarray:
        """(N, 3, 3): the covariance of one sensor reading at points p_sensor (N, 3), sensor frame, mm²."""
        p = np.asarray(p_sensor, float).reshape(-1, 3)
        if self.covariances is not None:
            return self.covariances(p)[0]
        if not self.polar:
            return np.broadcast_to(self.sigma_mm**2 * np.eye(3), (len(p), 3, 3)).copy()
        r = np.linalg.norm(p, axis=1)
        u = p / np.maximum(r, 1e-9)[:, None]
        sd = self.distance_mm + self.distance_ppm * 1e-6 * r
        st2 = self.floor_mm**2 + (self.angle_urad * 1e-6 * r) ** 2
        uu = u[:, :, None] * u[:, None, :]
        return sd[:, None, None] ** 2 * uu + st2[:, None, None] * (np.eye(3) - uu)

    def sensor_and_robot_cov(self, p_sensor) -> tuple[np.ndarray, np.ndarray]:
        """(`sensor_cov`, `robot_cov`) at the points p_sensor (N, 3): a model's own noise evaluated once for both."""
        if self.covariances is not None:
            return self.covariances(np.asarray(p_sensor, float).reshape(-1, 3))
        return self.sensor_cov(p_sensor), self.robot_cov(p_sensor)

    def robot_var(self) -> float:
        """The robot's per-axis variance, mm² (0 when not known)."""
        return float(self.robot_mm or 0.0) ** 2

    def robot_cov(self, p_sensor) -> np.ndarray:
        """(N, 3, 3): the covariance of the robot's reading of the points p_sensor (N, 3) (sensor frame), robot
        frame, mm²."""
        p = np.asarray(p_sensor, float).reshape(-1, 3)
        if self.covariances is not None:
            return self.covariances(p)[1]
        return np.broadcast_to(self.robot_var() * np.eye(3), (len(p), 3, 3)).copy()

    def to_json(self) -> dict:
        """``instrument`` in the JSON of `rrbc correct` (docs/cli.md)."""
        out: dict = {"name": self.name, "kind": "polar" if self.polar else "cartesian", "source": self.source}
        if self.polar:
            out.update(
                distance_mm=self.distance_mm,
                distance_ppm=self.distance_ppm,
                angle_urad=self.angle_urad,
                floor_mm=self.floor_mm,
            )
        else:
            out["sigma_mm"] = self.sigma_mm
        out.update(robot_mm=self.robot_mm, robot_source=self.robot_source)
        return out


def preset(name: str) -> Instrument:
    """The preset instrument `name` (one of `INSTRUMENTS`)."""
    if name not in PRESETS:
        raise InputError(f"--instrument {name!r}: not one of {', '.join(INSTRUMENTS)}")
    return Instrument(
        name=name, source=f"the {name} preset (makers' specifications, docs/uncertainty.md)", **PRESETS[name]
    )


def _checked(flag: str, value: float | None, limit: float) -> float | None:
    if value is None:
        return None
    v = float(value)
    if not np.isfinite(v) or v < 0 or v > limit:
        raise InputError(f"{flag} {value}: give a noise between 0 and {limit:g}")
    return v


def instrument_from_flags(
    name: str | None,
    sensor_noise_mm: float | None = None,
    distance_noise_mm: float | None = None,
    angle_noise_urad: float | None = None,
    robot_noise_mm: float | None = None,
) -> Instrument | None:
    """The instrument the command line describes, or None (everything estimated from the data).

    `name` picks a preset; `sensor_noise_mm` (per-axis σ) makes it cartesian, `distance_noise_mm` and
    `angle_noise_urad` make it polar (the other polar figures from the preset, else 0); `robot_noise_mm` is the
    robot's per-axis σ. A figure given overrides the preset's, and the source says so.
    """
    s = _checked("--sensor-noise-mm", sensor_noise_mm, MAX_SIGMA_MM)
    d = _checked("--distance-noise-mm", distance_noise_mm, MAX_SIGMA_MM)
    a = _checked("--angle-noise-urad", angle_noise_urad, MAX_ANGLE_URAD)
    r = _checked("--robot-noise-mm", robot_noise_mm, MAX_SIGMA_MM)
    if s is not None and (d is not None or a is not None):
        raise InputError(
            "--sensor-noise-mm is a per-axis noise; --distance-noise-mm and --angle-noise-urad a polar one: give one kind"
        )
    base = preset(name) if name is not None else None
    if base is None and s is None and d is None and a is None:
        if r is None:
            return None
        return Instrument(name="estimated", robot_mm=r, robot_source="given (--robot-noise-mm)")
    inst = base if base is not None else Instrument(name="given", polar=d is not None or a is not None)
    given = []
    if s is not None:
        if inst.polar and base is not None:
            raise InputError(
                f"--sensor-noise-mm: the {name} is a polar instrument; give --distance-noise-mm or --angle-noise-urad"
            )
        inst = replace(inst, polar=False, sigma_mm=s)
        given.append("--sensor-noise-mm")
    if d is not None or a is not None:
        if base is not None and not base.polar:
            raise InputError(
                f"--distance-noise-mm/--angle-noise-urad: the {name} preset is per-axis; give --sensor-noise-mm"
            )
        if d is not None:
            inst = replace(inst, distance_mm=d)
            given.append("--distance-noise-mm")
        if a is not None:
            inst = replace(inst, angle_urad=a)
            given.append("--angle-noise-urad")
    if given:
        what = ", ".join(given)
        inst = replace(inst, source=(f"{inst.source}, with {what} given" if base is not None else f"given ({what})"))
    if r is not None:
        inst = replace(inst, robot_mm=r, robot_source="given (--robot-noise-mm)")
    return inst


def scene_instrument(model, sensor_to_robot) -> Instrument:
    """A scene's own noise as the bounds' instrument: its error model's random terms (`models.measurement.
    MeasurementModel.noise_covariance`) at each point, placed in the robot frame by the scene's true sensor pose
    `sensor_to_robot` (tool down, time 0)."""

    def covariances(p_sensor: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p_robot = sensor_to_robot.apply(p_sensor)
        pts = model.points(p_robot, np.eye(3), np.zeros(len(p_robot)))
        return model.noise_covariance(pts)

    return Instrument(
        name="scene",
        source="the scene's error model (its noise terms at each point)",
        robot_mm=None,
        robot_source="the scene's error model",
        covariances=covariances,
    )
