"""A generated cell for the authoring tests: a seeded random bench (a box whose top is at z = 0) and a fixture
block on it, in the robot base frame, mm, with target holes on the fixture's top. Written as STL (one body per
box, not overlapping: the inside test's ray parity holds)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def random_cell(tmp: Path, seed: int, n_targets: int = 6) -> tuple[Path, Path, dict]:
    import trimesh

    rng = np.random.default_rng(seed)
    bench_w, bench_d = rng.uniform(900, 1300), rng.uniform(700, 900)
    bench = trimesh.creation.box(extents=(bench_w, bench_d, 40.0))
    bench.apply_translation((rng.uniform(350, 450), rng.uniform(-50, 50), -20.0))
    fw, fd, fh = rng.uniform(200, 320), rng.uniform(250, 380), rng.uniform(20, 60)
    fx, fy = rng.uniform(420, 520), rng.uniform(-80, 80)
    fixture = trimesh.creation.box(extents=(fw, fd, fh))
    fixture.apply_translation((fx, fy, fh / 2))
    mesh = trimesh.util.concatenate([bench, fixture])
    mesh_path = tmp / "cell.stl"
    mesh.export(mesh_path)
    xs = rng.uniform(fx - 0.35 * fw, fx + 0.35 * fw, n_targets)
    ys = rng.uniform(fy - 0.35 * fd, fy + 0.35 * fd, n_targets)
    targets = np.stack([xs, ys, np.full(n_targets, fh)], 1)
    lines = ["id,x,y,z,region_mm"] + [
        f"T{i + 1},{x:.3f},{y:.3f},{z:.3f},{3 + i % 2}" for i, (x, y, z) in enumerate(targets)
    ]
    targets_path = tmp / "targets.csv"
    targets_path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return mesh_path, targets_path, {"fixture": (fx, fy, fw, fd, fh), "targets": targets, "mesh": mesh}
