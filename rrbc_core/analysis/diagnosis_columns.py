"""The design columns of `rrbc diagnose`'s linearised residual model (`diagnosis_stats`): `Geometry` makes them at
the mapped points, and a design is one array (M, k) or its column blocks side by side (`Columns`), never stacked.

The model's own columns (translations, rotations, the linear map, drift) are simple functions of the points, so
`Geometry` gives them as `LazyColumns`: made a block of rows at a time when a product, a Gram matrix or a QR reads
them, never held whole (a million points would hold 24 MB a column, hundreds of MB a design). Every operation here
takes both kinds; `np.asarray` of lazy columns makes the array (what a test or a small design may want)."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

PLANAR_RATIO = 1e-2  # smallest/largest principal spread below this: the points are treated as coplanar

ROW_BLOCK = 1 << 15  # rows of a design made, multiplied or added up at a time


class LazyColumns:
    """Whitened, weighted columns (3N, k) of k vector fields over a `Geometry`'s N points, point-major (rows 3i,
    3i+1, 3i+2 are point i's x, y, z), made when read: `fill(sel, out)` writes the k fields in mm directions at the
    points `sel` (a slice or an index array) into out (k, P, 3) (zeros). Rows are read by slices (`x[a:b]`) or by
    points (`at_points`); either gives what `Geometry._cols` of the same fields gives at those rows."""

    def __init__(self, g: Geometry, k: int, fill: Callable[[Any, np.ndarray], None]):
        self._g = g
        self._k = k
        self._fill = fill

    @property
    def shape(self) -> tuple[int, int]:
        return (3 * self._g.n, self._k)

    def __len__(self) -> int:
        return 3 * self._g.n

    def _make(self, sel) -> np.ndarray:
        """The rows (3P, k) of the points sel, column-major (as `Geometry._cols` writes them)."""
        g = self._g
        sw = g.sw.reshape(g.n, 3)[sel]
        fields = np.zeros((self._k, len(sw), 3))
        self._fill(sel, fields)
        if not g.white_is_identity:  # (a field times the identity is itself: skipped)
            fields = fields @ g.white.T
        fields *= sw
        return fields.reshape(self._k, -1).T

    def at_points(self, points: np.ndarray) -> np.ndarray:
        """The rows (3M, k) of points (M,) (indices of the N points)."""
        return self._make(np.asarray(points, int))

    def __getitem__(self, key: slice) -> np.ndarray:
        if not isinstance(key, slice):
            raise TypeError("lazy columns are read by row slices (x[a:b]) or by points (at_points)")
        start, stop, step = key.indices(len(self))
        if step != 1:
            raise TypeError("lazy columns are read by contiguous row slices")
        if stop <= start:
            return np.zeros((0, self._k))
        p0, p1 = start // 3, -(-stop // 3)
        return self._make(slice(p0, p1))[start - 3 * p0 : stop - 3 * p0]

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        whole = self[0 : len(self)]
        return whole if dtype is None else whole.astype(dtype)


Block = np.ndarray | LazyColumns  # one block of a design
Columns = Block | tuple | list  # a design (M, k), or its column blocks side by side (no copy)


def column_blocks(x: Columns) -> list:
    """x's non-empty column blocks (arrays or `LazyColumns`), in order (blocks of blocks flattened)."""
    if not isinstance(x, (tuple, list)):
        return [x] if x.shape[1] else []
    return [b for part in x for b in column_blocks(part)]


def n_rows(x: Columns) -> int:
    return len(x) if not isinstance(x, (tuple, list)) else n_rows(x[0])


def as_array(x: Columns) -> np.ndarray:
    """The design x as one array (M, k): its column blocks side by side (a copy only when there are several or
    they are lazy)."""
    blocks = column_blocks(x)
    if len(blocks) == 1:
        return np.asarray(blocks[0])
    return np.hstack([np.asarray(b) for b in blocks]) if blocks else np.zeros((n_rows(x), 0))


def _all_arrays(blocks: list) -> bool:
    return all(isinstance(b, np.ndarray) for b in blocks)


def row_parts(blocks: list, rows: int) -> Iterable[tuple[int, int, list[np.ndarray]]]:
    """(start, stop, each block's rows start:stop) over the rows, `ROW_BLOCK` at a time."""
    for start in range(0, rows, ROW_BLOCK):
        stop = min(start + ROW_BLOCK, rows)
        yield start, stop, [b[start:stop] for b in blocks]


def gram(blocks: list) -> np.ndarray:
    """xᵀx (k, k) of the column blocks side by side."""
    edges = np.cumsum([0] + [b.shape[1] for b in blocks])
    out = np.zeros((edges[-1], edges[-1]))
    pairs = [(i, j) for i in range(len(blocks)) for j in range(i, len(blocks))]
    parts: Iterable = [(0, 0, blocks)] if _all_arrays(blocks) else row_parts(blocks, n_rows(blocks))
    for _, _, part in parts:
        for i, j in pairs:
            out[edges[i] : edges[i + 1], edges[j] : edges[j + 1]] += part[i].T @ part[j]
    for i, j in pairs:
        if i != j:
            out[edges[j] : edges[j + 1], edges[i] : edges[i + 1]] = out[
                edges[i] : edges[i + 1], edges[j] : edges[j + 1]
            ].T
    return out


def column_norms(blocks: list) -> np.ndarray:
    """The Euclidean norm of each column (k,) of the column blocks side by side."""
    if not blocks:
        return np.zeros(0)
    if _all_arrays(blocks):
        return np.concatenate([np.sqrt(np.einsum("ij,ij->j", b, b)) for b in blocks])
    sq = np.zeros(sum(b.shape[1] for b in blocks))
    for _, _, part in row_parts(blocks, n_rows(blocks)):
        sq += np.concatenate([np.einsum("ij,ij->j", b, b) for b in part])
    return np.sqrt(sq)


def times(x: Columns, a: np.ndarray) -> np.ndarray:
    """x @ a (M, j) for a design x (M, k) given as one array or as column blocks (arrays or lazy), without stacking
    the blocks: a block of rows at a time."""
    blocks = column_blocks(x)
    if len(blocks) == 1 and isinstance(blocks[0], np.ndarray):
        return blocks[0] @ a
    rows = n_rows(x)
    out = np.zeros((rows, a.shape[1]))
    edges = np.cumsum([0] + [b.shape[1] for b in blocks])
    for start, stop, part in row_parts(blocks, rows):
        into = out[start:stop]
        for b, lo, hi in zip(part, edges[:-1], edges[1:]):
            into += b @ a[lo:hi]
    return out


class Geometry:
    """Design columns of the linearised residual model at mapped points p (robot frame)."""

    def __init__(self, p: np.ndarray, time: np.ndarray | None, weights: np.ndarray, white: np.ndarray | None = None):
        self.white = np.eye(3) if white is None else white
        self.white_is_identity = bool(np.array_equal(self.white, np.eye(3)))
        self.center = p.mean(axis=0)
        c = p - self.center
        _, sv, vt = np.linalg.svd(c, full_matrices=False)
        self.axes = vt  # rows: principal directions
        self.planar = bool(sv[-1] <= PLANAR_RATIO * sv[0])
        self.normal = vt[2]
        self.scale = float(np.sqrt(np.mean(np.sum(c**2, axis=1)))) or 1.0
        u = c / self.scale
        if self.planar:  # exact rank deficiency on coplanar points: drop the normal coordinate
            u = u - np.outer(u @ self.normal, self.normal)
        self.u = u
        self.n = len(p)
        self.sw = np.repeat(np.sqrt(weights), 3)
        self.time = time
        self.tscale = float(np.std(time)) if time is not None else 1.0

    def vec(self, arr: np.ndarray) -> np.ndarray:
        """(N, 3) robot-frame vectors -> whitened, weighted (3N,)."""
        return (arr @ self.white.T).reshape(-1) * self.sw

    def _cols(self, fields, count: int | None = None) -> np.ndarray:
        """fields (k, N, 3), or an iterable of `count` (N, 3) fields -> whitened, weighted (3N, k), column-major
        (each column written in place: no (k, N, 3) copies of many points)."""
        if count is None:
            fields = list(fields) if not isinstance(fields, np.ndarray) else fields
            count = len(fields)
        out = np.empty((count, 3 * self.n)).T
        for j, f in enumerate(fields):
            np.multiply((np.asarray(f) @ self.white.T).reshape(-1), self.sw, out=out[:, j])
        return out

    def translations(self) -> LazyColumns:
        def fill(sel, out):
            for k in range(3):
                out[k, :, k] = 1.0

        return LazyColumns(self, 3, fill)

    def rigid(self) -> LazyColumns:
        def fill(sel, out):  # three moves, then the turns e_k x u
            u = self.u[sel]
            for k in range(3):
                out[k, :, k] = 1.0
            out[3, :, 1], out[3, :, 2] = -u[:, 2], u[:, 1]
            out[4, :, 0], out[4, :, 2] = u[:, 2], -u[:, 0]
            out[5, :, 0], out[5, :, 1] = -u[:, 1], u[:, 0]

        return LazyColumns(self, 6, fill)

    def scale_col(self) -> np.ndarray:
        return self._cols([self.u])

    def linear(self) -> LazyColumns:  # full 3x3 linear map: E_ab u
        def fill(sel, out):
            u = self.u[sel]
            for a in range(3):
                for b in range(3):
                    out[3 * a + b, :, a] = u[:, b]

        return LazyColumns(self, 9, fill)

    def drift(self) -> LazyColumns:
        assert self.time is not None, "the drift column needs the rows' times"
        tt = (self.time - self.time.mean()) / self.tscale

        def fill(sel, out):
            for k in range(3):
                out[k, :, k] = tt[sel]

        return LazyColumns(self, 3, fill)
