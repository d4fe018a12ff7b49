"""Generate the bundled example measurement file `example_measurements.csv` (seeded, deterministic).

Usage (from the repository root):  python rrbc_core/data/make_example.py [output.csv]

Scene (sensor frame, mm): a flat plate at z = 900 mm from the sensor; a 4 x 4 fiducial grid spans a 600 x 450 mm
region centred on the sensor axis (spacing 200 x 150 mm). The 4 grid corners have role `both` (registration and
fiducial) and are measured twice (start and end of the session); the 12 other grid points have role `fiducial`.
6 targets (role `target`, no robot values) and 10 check points (role `check`) lie inside the grid, 20 mm or more
from its edge.

Truth: p_robot = R p_sensor + t + bias(R p_sensor + t), with R = Rz(30°) Ry(1.5°) Rx(-2°), t = (850, -320, -880)
mm, and bias a smooth robot-side field: per axis a sum of two products of sines of wavelength 800 mm (four fiducial spacings) in robot x
and y with seeded phases, scaled to 0.3 mm RMS (over the three components) on a 61 x 46 grid of the plate region.
Sensor rows carry isotropic noise 0.02 mm per axis; robot-measured rows (both, fiducial) too; check rows carry the
noise-free robot truth (rigid transform of the true point plus the same bias: the robot takes its bias to the
target). Values are rounded to 1e-4 mm; times are seconds from the session start, 7 s per measurement.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

PARAMETERS = dict(
    seed=20240611,
    grid=(4, 4),
    size_mm=(600.0, 450.0),
    plate_z_mm=900.0,
    rotation_deg_zyx=(30.0, 1.5, -2.0),
    translation_mm=(850.0, -320.0, -880.0),
    bias_rms_mm=0.3,
    bias_wavelength_mm=800.0,
    noise_mm=0.02,
    n_targets=6,
    n_checks=10,
    margin_mm=20.0,
    decimals=4,
    seconds_per_row=7.0,
)


def _rotation(z_deg: float, y_deg: float, x_deg: float) -> np.ndarray:
    a, b, c = np.radians([z_deg, y_deg, x_deg])
    rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    rx = np.array([[1, 0, 0], [0, np.cos(c), -np.sin(c)], [0, np.sin(c), np.cos(c)]])
    return rz @ ry @ rx


def make_example(**overrides):
    """Return (MeasurementSet, comment lines) of the example; keyword arguments override PARAMETERS."""
    from rrbc_core.geometry.transforms import map_points
    from rrbc_core.io.measurements import MeasurementSet

    p = {**PARAMETERS, **overrides}
    rng = np.random.default_rng(p["seed"])
    nx, ny = p["grid"]
    sx, sy = p["size_mm"]
    z0 = p["plate_z_mm"]
    R = _rotation(*p["rotation_deg_zyx"])
    t = np.asarray(p["translation_mm"], dtype=float)
    k = 2 * np.pi / p["bias_wavelength_mm"]
    phases = rng.uniform(0, 2 * np.pi, size=(3, 2, 2))

    def raw_bias(q):  # robot-frame points (N, 3) -> (N, 3)
        x, y = q[:, 0], q[:, 1]
        cols = [
            np.sin(k * x + ph[0, 0]) * np.sin(k * y + ph[0, 1]) + np.sin(0.7 * k * x + ph[1, 0]) * np.sin(1.3 * k * y + ph[1, 1])
            for ph in phases
        ]
        return np.stack(cols, axis=1)

    gx, gy = np.meshgrid(np.linspace(-sx / 2, sx / 2, 61), np.linspace(-sy / 2, sy / 2, 46))
    dense = map_points(np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, z0)]), R, t)
    scale = p["bias_rms_mm"] / np.sqrt(np.mean(np.sum(raw_bias(dense) ** 2, axis=1)))

    def robot_truth(s):
        q = map_points(s, R, t)
        return q + scale * raw_bias(q)

    def noise(n):
        return rng.normal(0.0, p["noise_mm"], size=(n, 3))

    # grid points, row-major from the (-x, -y) corner
    xs = np.linspace(-sx / 2, sx / 2, nx)
    ys = np.linspace(-sy / 2, sy / 2, ny)
    grid_ids, grid_roles, grid_labels, grid_pts = [], [], [], []
    for r, y in enumerate(ys):
        for c, x in enumerate(xs):
            corner = r in (0, ny - 1) and c in (0, nx - 1)
            grid_ids.append(f"F{r + 1}{c + 1}")
            grid_roles.append("both" if corner else "fiducial")
            grid_labels.append(f"grid r{r + 1} c{c + 1}" + (" corner" if corner else ""))
            grid_pts.append((x, y, z0))
    grid_arr = np.array(grid_pts)
    m = p["margin_mm"]

    def inside(n):
        return np.column_stack(
            [rng.uniform(-sx / 2 + m, sx / 2 - m, n), rng.uniform(-sy / 2 + m, sy / 2 - m, n), np.full(n, z0)]
        )

    targets = inside(p["n_targets"])
    checks = inside(p["n_checks"])

    ids, roles, labels, true_rows, robot_rows = [], [], [], [], []
    for i in range(len(grid_arr)):  # session start: all grid points
        ids.append(grid_ids[i])
        roles.append(grid_roles[i])
        labels.append(grid_labels[i])
        true_rows.append(grid_arr[i])
        robot_rows.append(robot_truth(grid_arr[i : i + 1])[0] + noise(1)[0])
    for i in range(len(targets)):
        ids.append(f"T{i + 1}")
        roles.append("target")
        labels.append(f"target {i + 1}")
        true_rows.append(targets[i])
        robot_rows.append(np.full(3, np.nan))
    for i in range(len(checks)):
        ids.append(f"C{i + 1:02d}")
        roles.append("check")
        labels.append(f"check {i + 1}")
        true_rows.append(checks[i])
        robot_rows.append(robot_truth(checks[i : i + 1])[0])
    for i in range(len(grid_arr)):  # session end: corners measured again
        if grid_roles[i] == "both":
            ids.append(grid_ids[i])
            roles.append("both")
            labels.append(grid_labels[i] + " repeat")
            true_rows.append(grid_arr[i])
            robot_rows.append(robot_truth(grid_arr[i : i + 1])[0] + noise(1)[0])
    true_s = np.array(true_rows)
    sensor = true_s + noise(len(true_s))
    d = p["decimals"]
    sensor = np.round(sensor, d)
    robot = np.round(np.array(robot_rows), d)
    time = np.round(np.arange(len(ids)) * p["seconds_per_row"], 3)
    mset = MeasurementSet(
        ids=tuple(ids),
        roles=tuple(roles),
        sensor=sensor,
        robot=robot,
        time=time,
        lines=(0,) * len(ids),
        source="example_measurements.csv",
        extra={"label": tuple(labels)},
    )
    args = ", ".join(f"{key}={value!r}" for key, value in p.items())
    comments = [
        "RRBC example measurement file (units mm and s; sensor_* sensor frame, robot_* robot frame).",
        "generated by: python rrbc_core/data/make_example.py  (make_example() with the parameters below)",
        f"parameters: {args}",
        "scene: 4x4 fiducial grid on a 600 x 450 mm plate at sensor z = 900 mm; corners role both (measured twice),",
        "  others fiducial; 6 targets and 10 check points inside the grid.",
        "truth: robot = R sensor + t + bias(R sensor + t), R = Rz(30) Ry(1.5) Rx(-2) deg, t = (850, -320, -880) mm,",
        f"  bias = smooth sum of sine products (wavelength {p['bias_wavelength_mm']:g} mm) scaled to 0.3 mm RMS.",
        "noise: 0.02 mm per axis on sensor rows and robot-measured rows; check rows hold the noise-free robot truth.",
    ]
    return mset, comments


def main(argv=None) -> int:
    from rrbc_core.io.measurements_write import write_measurements

    argv = sys.argv[1:] if argv is None else argv
    out = Path(argv[0]) if argv else Path(__file__).with_name("example_measurements.csv")
    mset, comments = make_example()
    write_measurements(out, mset, comments)
    print(f"wrote {out} ({len(mset)} rows)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
