"""The baseline of `correct_1000000_rows` (issue 41, item 3): what a user would write with the obvious libraries
to compute `rrbc correct FILE --json`'s numbers for a measurement file, as a short script.

    python benchmarks/correct_baseline.py FILE > out.json

The file read by columns (pyarrow's CSV reader: what pandas' fastest engine uses; pandas itself is not a dependency
here), the least-squares registration of the registration rows (Kabsch / Umeyama, no scale), the fiducials'
corrections, inverse distance weighting (k = 4, p = 2, scipy's cKDTree) at every target and check, and the
command's numbers for each point (its sensor reading, correction, rigid and corrected positions; a check's truth,
errors and whether RRBC made it worse), written as JSON records (orjson, a C writer as fast as pandas'
`to_json`). No validation, no hull flags, no bounds, no warnings: it does less than the command, so the command
being no slower and no bigger than it is the stronger claim. The numbers agree with the command's (tests/io/test_correct_baseline.py,
on a small file).
"""

from __future__ import annotations

import sys

import numpy as np
import orjson
import pyarrow.csv as pcsv
from scipy.spatial import cKDTree


def baseline(path: str) -> dict:
    table = pcsv.read_csv(path, parse_options=pcsv.ParseOptions(), read_options=pcsv.ReadOptions())
    role = np.asarray(table.column("role").to_pylist(), dtype=object)
    ids = table.column("id").to_pylist()
    s = np.column_stack([table.column(c).to_numpy() for c in ("sensor_x", "sensor_y", "sensor_z")]).astype(float)
    b = np.column_stack([table.column(c).to_numpy() for c in ("robot_x", "robot_y", "robot_z")]).astype(float)
    reg = (role == "registration") | (role == "both")
    fid = (role == "fiducial") | (role == "both")
    # least-squares rigid transform robot = R sensor + t (Kabsch)
    cs, cb = s[reg].mean(axis=0), b[reg].mean(axis=0)
    u, _, vt = np.linalg.svd((s[reg] - cs).T @ (b[reg] - cb))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rot = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    t = cb - rot @ cs
    corr = (b[fid] - t) @ rot - s[fid]  # sensor frame: R^T (b - t) - s
    fid_ids = np.asarray(ids, dtype=object)[fid].tolist()
    out: dict = {
        "fiducials": [
            {"id": i, "sensor": p, "correction_mm": c} for i, p, c in zip(fid_ids, s[fid].tolist(), corr.tolist())
        ]
    }
    tree = cKDTree(s[fid])
    for name in ("target", "check"):
        rows = np.flatnonzero(role == name)
        if not len(rows):
            out[name + "s"] = []
            continue
        dist, idx = tree.query(s[rows], k=min(4, int(fid.sum())))
        w = 1.0 / np.maximum(dist, 1e-300) ** 2
        w /= w.sum(axis=1, keepdims=True)
        c = np.einsum("mk,mkc->mc", w, corr[idx])
        rigid = s[rows] @ rot.T + t
        rrbc = (s[rows] + c) @ rot.T + t
        rec = {
            "id": np.asarray(ids, dtype=object)[rows].tolist(),
            "sensor": s[rows].tolist(),
            "correction_mm": c.tolist(),
            "robot_rigid": rigid.tolist(),
            "robot_rrbc": rrbc.tolist(),
        }
        if name == "check":
            e_rigid = np.linalg.norm(rigid - b[rows], axis=1)
            e_rrbc = np.linalg.norm(rrbc - b[rows], axis=1)
            rec["robot_truth"] = b[rows].tolist()
            rec["error_rigid_mm"] = e_rigid.tolist()
            rec["error_rrbc_mm"] = e_rrbc.tolist()
            rec["rrbc_worse"] = (e_rrbc > e_rigid).tolist()
        keys = list(rec)
        out[name + "s"] = [dict(zip(keys, v)) for v in zip(*rec.values())]
    return out


if __name__ == "__main__":
    sys.stdout.buffer.write(orjson.dumps(baseline(sys.argv[1])))
    sys.stdout.buffer.write(b"\n")
