"""A stress scene for the drag benchmark (issue 4): the demo work cell with 200 fiducials (a 10 x 5 x 4 grid
around the fixture plate), 50 targets (a 10 x 5 grid on the plate, box regions) and, with 400 heat-map samples
per target, 20 000 heat-map samples. Written as a TOML file next to a copy of the demo mesh, so it goes through
the same loader as every scene."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
HEAT_SAMPLES_PER_TARGET = 400


def write_stress_scene(directory) -> Path:
    directory = Path(directory)
    (directory / "meshes").mkdir(parents=True, exist_ok=True)
    shutil.copy(ROOT / "scenes" / "meshes" / "demo_workcell.glb", directory / "meshes" / "demo_workcell.glb")
    demo = (ROOT / "scenes" / "demo_workcell.toml").read_text()
    head = demo.split("[[registration]]", 1)[0]
    regs = "".join(f"[[registration]]\n{m}" for m in demo.split("[[registration]]")[1:]).split("[[fiducial]]", 1)[0]
    tail = demo[demo.index("[error_model]"):] if "[error_model]" in demo else ""
    tail = re.sub(r"(?ms)^\[layouts\..*?(?=^\[(?!layouts))", "", tail)
    fid = []
    gx, gy, gz = np.meshgrid(np.linspace(300, 650, 10), np.linspace(-260, 260, 5), np.linspace(0, 150, 4), indexing="ij")
    for k, p in enumerate(np.c_[gx.ravel(), gy.ravel(), gz.ravel()]):
        fid.append(f'[[fiducial]]\nid = "S{k:03d}"\nposition = [{p[0]:.1f}, {p[1]:.1f}, {p[2]:.1f}]\n')
    tgt = []
    tx, ty = np.meshgrid(np.linspace(360, 590, 10), np.linspace(-180, 180, 5), indexing="ij")
    for k, (x, y) in enumerate(zip(tx.ravel(), ty.ravel())):
        tgt.append(f'[[target]]\nid = "T{k:02d}"\nposition = [{x:.1f}, {y:.1f}, 15.0]\n'
                   'region = { kind = "box", size = [4.0, 4.0, 1.0] }\n')
    text = head.replace('name = "Demo work cell"', 'name = "Stress cell"') + regs + "\n".join(fid) + "\n" + \
        "\n".join(tgt) + "\n" + tail
    out = directory / "stress.toml"
    out.write_text(text)
    return out
