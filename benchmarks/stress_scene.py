"""A stress scene for the drag benchmarks: the demo work cell — its robot, sensor, registration points, candidates,
simulation settings and FULL error model (UR5 kinematic bias with inverse kinematics per point, robot noise,
anisotropic sensor noise) — with 200 fiducials (a 10 x 5 x 4 grid around the fixture plate), 50 targets (a
10 x 5 grid on the plate, box regions) and, with 400 heat-map samples per target, 20 000 heat-map samples.

Written as a TOML file next to a copy of the demo mesh, so it goes through the same loader as every scene. The
demo's sections are kept whole (split at their headers), except its fiducials, targets and named layouts (which
name the demo's fiducials); `check_stress_scene` verifies that the error model survived.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "scenes" / "demo_workcell.toml"
HEAT_SAMPLES_PER_TARGET = 400
_DROPPED = re.compile(r"^\[\[(fiducial|target)\]\]|^\[layouts\.")


def _sections(text: str) -> list[str]:
    """The TOML text cut at each table header line (`[x]`, `[[x]]`); the first piece is the preamble."""
    return re.split(r"(?m)^(?=\[)", text)


def write_stress_scene(directory) -> Path:
    directory = Path(directory)
    (directory / "meshes").mkdir(parents=True, exist_ok=True)
    shutil.copy(ROOT / "scenes" / "meshes" / "demo_workcell.glb", directory / "meshes" / "demo_workcell.glb")
    kept = [s for s in _sections(DEMO.read_text()) if not _DROPPED.match(s)]
    text = "".join(kept).replace('name = "Demo work cell"', 'name = "Stress cell"')
    gx, gy, gz = np.meshgrid(
        np.linspace(300, 650, 10), np.linspace(-260, 260, 5), np.linspace(0, 150, 4), indexing="ij"
    )
    fid = [
        f'[[fiducial]]\nid = "S{k:03d}"\nposition = [{p[0]:.1f}, {p[1]:.1f}, {p[2]:.1f}]\n\n'
        for k, p in enumerate(np.c_[gx.ravel(), gy.ravel(), gz.ravel()])
    ]
    tx, ty = np.meshgrid(np.linspace(360, 590, 10), np.linspace(-180, 180, 5), indexing="ij")
    tgt = [
        f'[[target]]\nid = "T{k:02d}"\nposition = [{x:.1f}, {y:.1f}, 15.0]\n'
        'region = { kind = "box", size = [4.0, 4.0, 1.0] }\n\n'
        for k, (x, y) in enumerate(zip(tx.ravel(), ty.ravel()))
    ]
    out = directory / "stress.toml"
    out.write_text(text.rstrip() + "\n\n" + "".join(fid) + "".join(tgt))
    check_stress_scene(out)
    return out


def check_stress_scene(path) -> None:
    """Raise AssertionError unless the stress scene has the demo's error model, robot and sensor, 200 fiducials
    and 50 targets (what the benchmark's notes claim)."""
    from rrbc_core.io.scene_toml import load_scene

    demo, stress = load_scene(DEMO), load_scene(path)
    assert repr(stress.error_model) == repr(demo.error_model), "the stress scene lost the demo's error model"
    assert stress.error_model.deterministic().robot, "the stress scene has no robot bias"
    assert np.allclose(stress.sensor_position, demo.sensor_position)
    assert len(stress.fiducials) == 200 and len(stress.targets) == 50
