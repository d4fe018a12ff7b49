"""Example 2: simulate a work cell, as `rrbc simulate SCENE` does, and write one simulated data set.

Run: .venv/bin/python examples/02_simulate_a_scene.py [SCENE.toml] [--out data.csv]   (default: the bundled scene)

A scene (scenes/*.toml) states the robot, the sensor, their error models and where the registration points,
fiducials and targets are. `simulate` runs a Monte Carlo over noise; `simulated_data` measures the cell once and
returns what a measurement file holds (what `rrbc simulate --out` writes), ready for `rrbc correct` or example 1.
"""

import argparse

import rrbc_core as rrbc

parser = argparse.ArgumentParser()
parser.add_argument("scene", nargs="?", default=None, help="scene TOML (default: the bundled work cell)")
parser.add_argument("--out", default=None, help="also write one simulated measurement file here")
parser.add_argument("--trials", type=int, default=100)
args = parser.parse_args()

scene = rrbc.load_scene(args.scene or rrbc.default_scene_path())
mc = rrbc.simulate(scene, trials=args.trials, seed=1)  # seeded: the same numbers every run
print(f"{mc.scene}: {mc.trials} trials, {mc.n_registration} registration points, {mc.n_fiducials} fiducials")
for s in mc.strategies:
    print(f"  {s.name:>14}: rigid RMS {s.tre_rms_mm:.3f} mm -> RRBC (IDW) {s.rmst_rrbc_mm:.3f} mm")
for i in mc.interpolations:
    print(f"  least squares + {i.name:>6}: RMST {i.rmst_mm:.3f} mm")

if args.out:
    data = rrbc.simulated_data(scene, seed=1)
    rrbc.write_measurements(args.out, data)  # atomic: never a partial file
    print(f"wrote {len(data.ids)} rows to {args.out}")
