"""The import's neighbourhood work in the compiled core: the local float32 frame, the k-d tree
(PointIndex), the exact-duplicate search, and the row renumbering the graph work uses."""
from __future__ import annotations

from typing import Optional

import numpy as np

from .. import _core
from ..util.arrays import as_f32, as_indices
from ..util.columns import bounds, in_blocks


def local_frame(points: np.ndarray, bulk: Optional[np.ndarray] = None,
                rounding: Optional[np.ndarray] = None) -> tuple[np.ndarray, np.ndarray]:
    """Splits float64 (or float32) points into (origin, float32 offsets from it).

    The origin is the centre of the bounding box (of the points selected by the boolean
    mask `bulk`, when given: the importer leaves stray points out, so that one point far
    away cannot move it), rounded to a float32 value so that it can be stored exactly
    (e.g. as a Blender object location). Subtracting it in float64 before the cast keeps
    full precision for georeferenced scans (1e5 to 1e7 metres).
    `rounding`, an (N,) float32 array when given, receives how far the float32 rounding moved
    each point (its largest coordinate's error), from the same float64 differences.
    """
    pts = np.asarray(points)
    if pts.dtype != np.float32:  # float32 points are subtracted in float64 block by block below: no copy
        pts = pts.astype(np.float64, copy=False)
    if pts.size == 0:
        return np.zeros(3), np.zeros((0, 3), np.float32)
    mask = None if bulk is None else np.asarray(bulk, bool)
    # a copy of the bulk only when it leaves points out (10M points: 240 MB and a second)
    box = pts if mask is None or mask.all() or not mask.any() else pts[mask]
    lo, hi = bounds(box)
    origin = ((lo + hi) * 0.5).astype(np.float32).astype(np.float64)
    local = np.empty(pts.shape, np.float32)

    def block(b: int, e: int) -> None:  # the difference in float64, rounded once, with no float64 temporary
        np.subtract(pts[b:e], origin, out=local[b:e], casting="same_kind")

    def block_and_rounding(b: int, e: int) -> None:  # a float64 temporary of one block for the error
        exact = pts[b:e] - origin
        local[b:e] = exact
        rounding[b:e] = np.abs(exact - local[b:e]).max(axis=1)

    in_blocks(block if rounding is None else block_and_rounding, len(pts))
    return origin, local


class PointIndex:
    """k nearest neighbours among float32 points: a k-d tree in the compiled core
    (native/pointcloud/neighbours.h), for the import's neighbourhood work (spacing.py, normals.py).

        index = PointIndex(points)                # (N,3)
        dist, ids = index.knn(index.order[:1000], k=6)

    Queries name points of the index by row and return their k nearest *other* points,
    nearest first (distances, ids); `knn_at` asks about any positions. Walking `order` (the
    tree's order: neighbouring points are adjacent) in chunks keeps each chunk's queries in
    one part of the tree, and lets the caller report progress and cancel between chunks.
    threads: 0 for all cores."""

    def __init__(self, points: np.ndarray, threads: int = 0):
        self.points = as_f32(points, "points", (-1, 3))
        self.threads = int(threads)
        self._index = _core.PointIndex(self.points, self.threads)
        self.order = np.empty(len(self.points), np.int32)
        self._index.order(self.order)

    def __len__(self) -> int:
        return len(self.points)

    @staticmethod
    def _rows(rows) -> np.ndarray:
        return np.ascontiguousarray(rows, dtype=np.int32).reshape(-1)

    def knn(self, rows, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(dist float32 (m,k), ids int32 (m,k)): each row's k nearest other points."""
        rows = self._rows(rows)
        dist, ids = np.empty((len(rows), k), np.float32), np.empty((len(rows), k), np.int32)
        self._index.knn(rows, k, dist, ids, self.threads)
        return dist, ids

    def knn_at(self, positions, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(dist, ids) of the k nearest points of the index to each (m,3) position."""
        pos = as_f32(positions, "positions", (-1, 3))
        dist, ids = np.empty((len(pos), k), np.float32), np.empty((len(pos), k), np.int32)
        self._index.knn_at(pos, k, dist, ids, self.threads)
        return dist, ids

    def kth_distance(self, rows, k: int) -> np.ndarray:
        """(m,) float32: each row's distance to its k-th nearest other point (`radii`
        without the gap-closing radii)."""
        return self.radii(rows, k)[0]

    def covering(self, rows, normals: np.ndarray, spacing: np.ndarray, k: int, hole: float, max_gap: float
                 ) -> np.ndarray:
        """(m,) float32 gap-closing radii (spacing.covering_radii's rule: the largest empty
        circle through the point and two angularly adjacent neighbours among its k nearest,
        in its tangent plane, when between spacing and hole x spacing and not across an
        angular gap of max_gap radians or more). normals (N,3) (directions, any length) and spacing (N,) are per
        point of the index."""
        rows = self._rows(rows)
        out = np.empty(len(rows), np.float32)
        self._index.covering(rows, as_f32(normals, "normals", (len(self), 3)), as_f32(spacing, "spacing", (len(self),)),
                             k, float(hole), float(max_gap), out, self.threads)
        return out

    def radii(self, rows, spacing_k: int, normals: Optional[np.ndarray] = None, cover_k: int = 0, hole: float = 0.0,
              max_gap: float = 0.0, out=None, cover_cap: float = 0.0) -> tuple[np.ndarray, Optional[np.ndarray]]:
        """(spacing (m,) float32, cover (m,) float32 or None) from one search: each row's
        distance to its spacing_k-th nearest other point and, given normals ((N,3), any length),
        its gap-closing radius among its cover_k nearest with that distance as the spacing
        (`covering`'s rule). out: (spacing, cover) float32 arrays (N,) (cover None without
        normals) to write each row's values into at the row's own place (rows: distinct),
        instead of new (m,) arrays; they are returned. cover_cap >= 1: each cover is kept
        between the row's spacing and cover_cap times it (0: as the rule gives it)."""
        rows = self._rows(rows)
        by_row = out is not None
        if by_row:
            spacing, cover = out
            if (cover is None) != (normals is None):
                raise ValueError("out needs a cover array exactly when normals are given")
        else:
            spacing = np.empty(len(rows), np.float32)
            cover = None if normals is None else np.empty(len(rows), np.float32)
        if normals is None:
            self._index.radii(rows, spacing_k, spacing, threads=self.threads, by_row=by_row)
        else:
            self._index.radii(rows, spacing_k, spacing, as_f32(normals, "normals", (len(self), 3)), cover_k,
                              float(hole), float(max_gap), cover, self.threads, by_row, float(cover_cap))
        return spacing, cover

    def widest_gaps(self, rows, normals: np.ndarray, k: int) -> np.ndarray:
        """(m,) float32: each row's widest angle (radians) between angularly adjacent
        neighbours among its k nearest, seen in its tangent plane, those below it unfolded
        along their normals' tilt (spacing.py's boundary test). normals (N,3) by id, any
        length but 0, float32 (no copy) or converted."""
        rows = self._rows(rows)
        out = np.empty(len(rows), np.float32)
        self._index.widest_gaps(rows, k, as_f32(normals, "normals", (len(self), 3)), out, self.threads)
        return out

    def pca(self, rows, k: int, graph_width: int = 0, spacing_k: int = 0, cover_k: int = 0, hole: float = 0.0,
            max_gap: float = 0.0):
        """(normals float64 (m,3), graph int32 (m, graph_width) or None, spacing float32 (m,)
        or None, cover float32 (m,) or None) from one search: each row's PCA normal over
        itself and its k nearest (unoriented); the graph holds the row itself, then its
        graph_width - 1 nearest; spacing, the distance to its spacing_k-th nearest other
        point; cover (cover_k > 0, needs spacing_k), its gap-closing radius among its
        cover_k nearest with its PCA normal and that spacing (`covering`'s rule)."""
        rows = self._rows(rows)
        normals = np.empty((len(rows), 3))
        graph = np.empty((len(rows), graph_width), np.int32) if graph_width else None
        spacing = np.empty(len(rows), np.float32) if spacing_k else None
        cover = np.empty(len(rows), np.float32) if cover_k else None
        self._index.pca(rows, k, normals, graph, spacing_k, spacing, cover_k, float(hole), float(max_gap), cover,
                        self.threads)
        return normals, graph, spacing, cover


def spatial_order(points, threads: int = 0) -> np.ndarray:
    """(n,) int32: the indices of the (n,3) points (as float64, finite) in Morton order over
    their bounding box: a renumbering under which the graph functions below read memory
    mostly in cache (see native/pointcloud/graph.h)."""
    pts = np.ascontiguousarray(points, dtype=np.float64)
    out = np.empty(len(pts), np.int32)
    _core.spatial_order(pts, out, threads=threads)
    return out


def first_of_duplicates(points, threads: int = 0) -> np.ndarray:
    """(n,) bool: True for each row of the (n,3) points (float32, else as float64) whose position no
    earlier row has. Positions are equal when their coordinates are equal as numbers: -0.0
    equals 0.0, an infinity equals itself, and a row with a NaN coordinate equals no row
    (it is always True). Coincident points make the k-NN query pathological (every neighbour
    at distance 0: 200k copies of one point took 90 s), so the importer finds them first
    (cloud.make_cloud). Rows are bucketed and sorted by a hash of their coordinates in the
    compiled core (see native/pointcloud/duplicates.h), and only rows sharing a hash are compared by
    value, in about linear time however many copies there are; on `threads` threads (0: all
    cores; the result does not depend on them). 10M random float32-sourced points on two
    threads: 0.08 s against 1.0 s for the numpy's hash and sort, and 0.17 s against 11 s
    when they are 1M positions ten times each."""
    pts = np.asarray(points)  # float32 as it is (a float32 file's coordinates), else float64
    pts = np.ascontiguousarray(pts, dtype=np.float32 if pts.dtype == np.float32 else np.float64)
    out = np.empty(len(pts), bool)
    _core.first_of_duplicates(pts, out, threads=threads)
    return out


def permute_table(table, order, columns: Optional[slice] = None, threads: int = 0) -> np.ndarray:
    """The neighbour table renumbered by `order` (a permutation): row r is row order[r] of
    `table` (its `columns`, a slice with step 1; default all), each entry replaced by that
    point's position in `order`."""
    t = as_indices(table, "table", (-1, -1))
    first, stop, step = (columns or slice(None)).indices(t.shape[1])
    if step != 1:
        raise ValueError("columns must be a slice with step 1")
    out = np.empty((len(t), max(stop - first, 0)), np.int32)
    _core.permute_table(t, as_indices(order, "order", (len(t),)), first, out, threads=threads)
    return out


def take_rows(array, order, threads: int = 0) -> np.ndarray:
    """array[order] for an (n,c) array (as float64) and row numbers `order`: numpy's fancy
    indexing in parallel, fetching rows ahead (10M rows of 3 in random order: 0.1-0.3 s
    against numpy's 0.7-0.9 s, best of 4 on the shared machine)."""
    a = np.ascontiguousarray(array, dtype=np.float64)
    if a.ndim != 2:
        raise ValueError(f"array must have 2 dimensions, got shape {a.shape}")
    o = as_indices(order, "order", (-1,))
    out = np.empty((len(o), a.shape[1]), np.float64)
    _core.take_rows(a, o, out, threads=threads)
    return out
