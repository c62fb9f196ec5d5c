"""The splat ray tracer's core, usable from plain Python (no Blender needed).

    from splat_tracer import core
    scene = core.Scene(centres, normals, radii, closed=True)  # (N,3), (N,3), (N,) arrays
    surf = scene.trace_surface(origins, directions)            # the paper's visibility method
    hits = scene.trace(origins, directions)                    # plain nearest hit per ray
    cam = core.Camera.look_at(eye, target, fov_y=40, aspect=4/3)
    image = scene.render(cam, 640, 480, method=core.Method.preset("FULL"))

Everything heavy runs in the compiled module `_core` (BVH, intersection, threads). This
file turns numpy arrays into the contiguous float32 buffers it wants and allocates the
outputs. Coordinates are those of one local frame: a caller with georeferenced data
subtracts a float64 origin first (see `local_frame`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, NamedTuple, Optional, Sequence

import numpy as np

from . import _core, matrices
from .columns import bounds, in_blocks

PARALLEL_COSINE = _core.PARALLEL_COSINE
MAX_LAYER_HITS = _core.MAX_LAYER_HITS  # per-ray hit buffer of the ε-window query
hardware_threads = _core.hardware_threads
simd_path = _core.simd_path  # 'SSE2' or 'plain floats': the BVH's box and disc tests

POSITION_RULES = ("FIRST", "NEAR_PHASE", "NEAREST_CENTRE")
KERNELS = ("LINEAR", "SMOOTH")
PRESETS = ("GENERAL", "NEAREST_CENTRE", "FULL")


@dataclass(frozen=True)
class Method:
    """Which surface a ray sees and how it is shaded (docs/ALGORITHM.md); each rule a switch.

    eliminate_wrong_hits: hits of the wrong facing before the first layer are ignored.
    interpolate_normals: normal and colour blended over the layer's splats, weighted by
        `kernel` ('LINEAR': the paper's (r - d)/r; 'SMOOTH': (1 - (d/r)^2)^2); off: flat.
    far_phase: on closed objects, a layer counts only if the next hit after it leaves the
        object (has the other facing); otherwise the search goes on along the ray.
    position: the surface point within the layer: 'FIRST' hit, 'NEAR_PHASE' (the paper's
        convex/concave rule) or 'NEAREST_CENTRE' (Linsen et al.).
    epsilon: depth of a layer, in radii of its first splat.
    crease_angle: degrees; with interpolation, only the layer's splats whose normal is within
        this angle of the surface splat's blend (sharp edges stay sharp, like Auto Smooth);
        180: every splat blends (the paper's).
    """

    eliminate_wrong_hits: bool = True
    interpolate_normals: bool = True
    far_phase: bool = True
    position: str = "NEAR_PHASE"
    kernel: str = "LINEAR"
    epsilon: float = 1.0
    crease_angle: float = 180.0

    def __post_init__(self):
        if self.position not in POSITION_RULES:
            raise ValueError(f"position must be one of {POSITION_RULES}, got {self.position!r}")
        if self.kernel not in KERNELS:
            raise ValueError(f"kernel must be one of {KERNELS}, got {self.kernel!r}")
        if not (np.isfinite(self.epsilon) and self.epsilon >= 0):
            raise ValueError(f"epsilon must be a finite number >= 0, got {self.epsilon!r}")
        if not (0 <= self.crease_angle <= 180):
            raise ValueError(f"crease_angle must be between 0 and 180 degrees, got {self.crease_angle!r}")

    @classmethod
    def preset(cls, name: str, **overrides) -> "Method":
        """'GENERAL': nearest hit, any facing, flat normal. 'NEAREST_CENTRE' (Linsen et al.):
        wrong hits eliminated, interpolated normals, the layer hit nearest its disc centre.
        'FULL': every rule of the paper."""
        presets = {
            "GENERAL": dict(eliminate_wrong_hits=False, interpolate_normals=False, far_phase=False,
                            position="FIRST"),
            "NEAREST_CENTRE": dict(eliminate_wrong_hits=True, interpolate_normals=True, far_phase=False,
                                   position="NEAREST_CENTRE"),
            "FULL": dict(eliminate_wrong_hits=True, interpolate_normals=True, far_phase=True,
                         position="NEAR_PHASE"),
        }
        if name not in presets:
            raise ValueError(f"preset must be one of {PRESETS}, got {name!r}")
        return cls(**{**presets[name], **overrides})

    def as_tuple(self) -> tuple:
        return (self.eliminate_wrong_hits, self.interpolate_normals, self.far_phase,
                POSITION_RULES.index(self.position), KERNELS.index(self.kernel), float(self.epsilon),
                float(self.crease_angle))


def _f32(a, name: str, shape: tuple) -> np.ndarray:
    arr = np.ascontiguousarray(a, dtype=np.float32)
    if arr.ndim != len(shape) or any(s not in (-1, d) for s, d in zip(shape, arr.shape)):
        want = "x".join("N" if s == -1 else str(s) for s in shape)
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    return arr


def local_frame(points: np.ndarray, bulk: Optional[np.ndarray] = None) -> tuple[np.ndarray, np.ndarray]:
    """Splits float64 (or float32) points into (origin, float32 offsets from it).

    The origin is the centre of the bounding box (of the points selected by the boolean
    mask `bulk`, when given: the importer leaves stray points out, so that one point far
    away cannot move it), rounded to a float32 value so that it can be stored exactly
    (e.g. as a Blender object location). Subtracting it in float64 before the cast keeps
    full precision for georeferenced scans (1e5 to 1e7 metres).
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

    in_blocks(block, len(pts))
    return origin, local


class PointIndex:
    """k nearest neighbours among float32 points: a k-d tree in the compiled core
    (native/pointcloud/neighbours.h), for the import's neighbourhood work (spacing.py, normals.py).

        index = core.PointIndex(points)           # (N,3)
        dist, ids = index.knn(index.order[:1000], k=6)

    Queries name points of the index by row and return their k nearest *other* points,
    nearest first (distances, ids); `knn_at` asks about any positions. Walking `order` (the
    tree's order: neighbouring points are adjacent) in chunks keeps each chunk's queries in
    one part of the tree, and lets the caller report progress and cancel between chunks.
    threads: 0 for all cores."""

    def __init__(self, points: np.ndarray, threads: int = 0):
        self.points = _f32(points, "points", (-1, 3))
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
        pos = _f32(positions, "positions", (-1, 3))
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
        self._index.covering(rows, _f32(normals, "normals", (len(self), 3)), _f32(spacing, "spacing", (len(self),)),
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
            self._index.radii(rows, spacing_k, spacing, _f32(normals, "normals", (len(self), 3)), cover_k, float(hole),
                              float(max_gap), cover, self.threads, by_row, float(cover_cap))
        return spacing, cover

    def widest_gaps(self, rows, normals: np.ndarray, k: int) -> np.ndarray:
        """(m,) float32: each row's widest angle (radians) between angularly adjacent
        neighbours among its k nearest, seen in its tangent plane, those below it unfolded
        along their normals' tilt (spacing.py's boundary test). normals (N,3) by id, any
        length but 0, float32 (no copy) or converted."""
        rows = self._rows(rows)
        out = np.empty(len(rows), np.float32)
        self._index.widest_gaps(rows, k, _f32(normals, "normals", (len(self), 3)), out, self.threads)
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


# --- neighbour graphs (normals.orient's propagation; native/pointcloud/graph.h) -----------
# `progress` here is None or a callable taking the fraction done (0..1) of the call, run on
# the calling thread between chunks of work; an exception from it stops the work and
# propagates (progress.Cancelled). `threads`: 0 for all cores.

class SpanningForest(NamedTuple):
    edges: np.ndarray   # (n - components, 2) int32: the forest's edges, as vertex pairs
    labels: np.ndarray  # (n,) int32: each vertex's connected component, numbered by smallest vertex
    components: int


def _indices(a, name: str, shape: tuple) -> np.ndarray:
    """`a` as a C-contiguous int32 array of `shape` (-1: any size); other integer types are
    range-checked before the conversion (an int64 index beyond int32 would otherwise wrap
    into a valid one)."""
    arr = np.asarray(a)
    if arr.ndim != len(shape) or any(s not in (-1, d) for s, d in zip(shape, arr.shape)):
        want = "x".join("N" if s == -1 else str(s) for s in shape)
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    if arr.dtype != np.int32:
        if arr.dtype.kind not in "iu":
            raise TypeError(f"{name} must hold integers, got {arr.dtype}")
        info = np.iinfo(np.int32)
        if arr.size and (arr.min() < info.min or arr.max() > info.max):
            raise ValueError(f"{name} holds values beyond int32 ({arr.min()} to {arr.max()}): not vertex indices")
    return np.ascontiguousarray(arr, dtype=np.int32)


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
    (it is always True). Hashing, bucketing and sorting in the compiled core (see
    native/pointcloud/duplicates.h), on `threads` threads (0: all cores; the result does not depend on
    them). 10M random float32-sourced points on two threads: 0.08 s against 1.0 s for the
    numpy version it replaced, and 0.17 s against 11 s when they are 1M positions ten times
    each (spacing.first_of_duplicates says why it matters)."""
    pts = np.asarray(points)  # float32 as it is (a float32 file's coordinates), else float64
    pts = np.ascontiguousarray(pts, dtype=np.float32 if pts.dtype == np.float32 else np.float64)
    out = np.empty(len(pts), bool)
    _core.first_of_duplicates(pts, out, threads=threads)
    return out


def permute_table(table, order, columns: Optional[slice] = None, threads: int = 0) -> np.ndarray:
    """The neighbour table renumbered by `order` (a permutation): row r is row order[r] of
    `table` (its `columns`, a slice with step 1; default all), each entry replaced by that
    point's position in `order`."""
    t = _indices(table, "table", (-1, -1))
    first, stop, step = (columns or slice(None)).indices(t.shape[1])
    if step != 1:
        raise ValueError("columns must be a slice with step 1")
    out = np.empty((len(t), max(stop - first, 0)), np.int32)
    _core.permute_table(t, _indices(order, "order", (len(t),)), first, out, threads=threads)
    return out


def take_rows(array, order, threads: int = 0) -> np.ndarray:
    """array[order] for an (n,c) array (as float64) and row numbers `order`: numpy's fancy
    indexing in parallel, fetching rows ahead (10M rows of 3 in random order: 0.1-0.3 s
    against numpy's 0.7-0.9 s, best of 4 on the shared machine)."""
    a = np.ascontiguousarray(array, dtype=np.float64)
    if a.ndim != 2:
        raise ValueError(f"array must have 2 dimensions, got shape {a.shape}")
    o = _indices(order, "order", (-1,))
    out = np.empty((len(o), a.shape[1]), np.float64)
    _core.take_rows(a, o, out, threads=threads)
    return out


def graph_weights(points, normals, neighbours, across: float = 1.0, threads: int = 0,
                  progress: Optional[Callable[[float], None]] = None) -> np.ndarray:
    """(n,k) float32 weights of the edges of the neighbour table (row i: the k points joined
    to point i): 1 - |n_i . n_j| + across * (|n_i . d| + |n_j . d|) / 2, d the edge's unit
    direction (normals.py says why). points, normals: (n,3), as float64."""
    pts = np.ascontiguousarray(points, dtype=np.float64)
    nrm = np.ascontiguousarray(normals, dtype=np.float64)
    nbr = _indices(neighbours, "neighbours", (-1, -1))
    out = np.empty(nbr.shape, np.float32)
    _core.graph_weights(pts, nrm, nbr, float(across), out, threads=threads, progress=progress)
    return out


def spanning_forest(neighbours, weights, threads: int = 0,
                    progress: Optional[Callable[[float], None]] = None) -> SpanningForest:
    """The minimum spanning forest of the neighbour table's graph (row i: the k points joined
    to point i; an entry i in row i is no edge) under `weights` ((n,k), finite, as float32),
    ties broken by the entries' order (row-major): deterministic for any number of threads."""
    nbr = _indices(neighbours, "neighbours", (-1, -1))
    w = _f32(weights, "weights", nbr.shape)
    n = len(nbr)
    edges = np.empty((max(n - 1, 0), 2), np.int32)
    labels = np.empty(n, np.int32)
    m, components = _core.spanning_forest(nbr, w, edges, labels, threads=threads, progress=progress)
    return SpanningForest(edges[:m], labels, components)


def forest_traversal(edges, anchors, progress: Optional[Callable[[float], None]] = None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Breadth-first traversal of the undirected graph of `edges` ((m,2) vertex pairs) from
    all `anchors` ((n,) bool) at once: (parent, order), parent (n,) int32 the vertex each one
    was reached from (an anchor: itself; not reached: -1), order the reached vertices in the
    order visited (anchors first, in increasing order)."""
    e = _indices(edges, "edges", (-1, 2))
    a = np.ascontiguousarray(anchors, dtype=bool)
    if a.ndim != 1:
        raise ValueError(f"anchors must be one flag per vertex, got shape {a.shape}")
    parent = np.empty(len(a), np.int32)
    order = np.empty(len(a), np.int32)
    reached = _core.forest_traversal(e, a, parent, order, progress=progress)
    return parent, order[:reached]


def chain_flips(order, parent, flip) -> np.ndarray:
    """(n,) bool: each vertex's sign is negative, when each vertex of `order` (each after its
    parent: forest_traversal's) takes its parent's sign, flipped where `flip`, and a vertex
    that is its own parent is negative where `flip`. Vertices not in order: their flip."""
    p = _indices(parent, "parent", (-1,))
    o = _indices(order, "order", (-1,))
    f = np.ascontiguousarray(flip, dtype=bool)
    if f.shape != p.shape:
        raise ValueError(f"flip must have one entry per vertex ({len(p)}), got shape {f.shape}")
    out = np.empty(len(p), bool)
    _core.chain_flips(o, p, f, out)
    return out


def _window(window, width: int, height: int) -> tuple[int, int, int, int]:
    """(x0, y0, w, h) of a render window, checked before its buffers are allocated (a bad
    window such as (-1, -1, 1, 2**31 - 1) used to ask numpy for 34 GB before the core
    refused it)."""
    x0, y0, w, h = (int(v) for v in (window if window is not None else (0, 0, width, height)))
    if not (width > 0 and height > 0 and 0 <= x0 and 0 <= y0 and w > 0 and h > 0 and x0 + w <= width
            and y0 + h <= height):
        raise ValueError(f"window ({x0}, {y0}, {w}, {h}) is not inside the {width}x{height} image")
    return x0, y0, w, h


PACKET_RAYS = _core.PACKET_RAYS  # rays Scene.trace / trace_surface take through the tree at once


def packet_order(width: int, height: int) -> np.ndarray:
    """Indices that put row-major pixel rays (Camera.rays) in 4x4 tiles, left to right and
    top to bottom (16 consecutive rays: one tile, one packet for trace() and
    trace_surface()); the inverse permutation is np.argsort of it."""
    if not (width > 0 and height > 0):
        raise ValueError(f"width and height must be positive, got {width}x{height}")
    side = math.isqrt(PACKET_RAYS)  # the core's blocks: 4x4
    rows, cols = np.divmod(np.arange(width * height), width)
    return np.lexsort((cols, rows, cols // side, rows // side))


class TraceResult(NamedTuple):
    t: np.ndarray       # (N,) float32 distance along the normalised direction; inf on a miss
    id: np.ndarray      # (N,) int32 splat index, -1 on a miss
    front: np.ndarray   # (N,) bool, the ray meets the side the splat normal points to
    normal: Optional[np.ndarray]  # (N,3) float32 splat normal (zeros on a miss), if asked for


class SurfaceResult(NamedTuple):
    t: np.ndarray        # (N,) distance to the surface point; inf on a miss
    id: np.ndarray       # (N,) the splat whose hit is the surface point, -1 on a miss
    front: np.ndarray    # (N,) bool, facing of that hit
    normal: np.ndarray   # (N,3) shading normal (interpolated or flat); zeros on a miss
    colour: np.ndarray   # (N,3) blended colour
    members: Optional[np.ndarray]  # (N, MAX_LAYER_HITS) int32: the layer's splats, -1 padded


class RenderResult(NamedTuple):
    rgba: np.ndarray                # (h, w, 4) float32, top row first
    depth: Optional[np.ndarray]     # (h, w) planar depth along the view axis; 1e10 on background
    normal: Optional[np.ndarray]    # (h, w, 3) unit normals; zeros on background
    completed: bool                 # False when progress() asked to stop


@dataclass(frozen=True)
class Camera:
    """A pinhole or orthographic camera, as the core consumes it.

    local_from_ndc: 4x4 float64 mapping OpenGL normalised device coordinates (z = -1 on the
    near clipping plane, +1 on the far one) to points of the scene's local frame.
    position / forward: camera centre and unit view axis, for planar depth.
    """

    local_from_ndc: np.ndarray
    position: np.ndarray
    forward: np.ndarray

    @classmethod
    def from_view_projection(cls, projection, world_from_camera, origin=(0.0, 0.0, 0.0)) -> "Camera":
        """From a projection matrix (camera space to clip space, OpenGL convention, as
        Blender's `Object.calc_matrix_camera` returns) and the camera's rigid world matrix
        (looking down its local -Z); `origin` is the scene's local-frame origin."""
        proj = np.asarray(projection, dtype=np.float64).reshape(4, 4)
        w_c = np.asarray(world_from_camera, dtype=np.float64).reshape(4, 4)
        local_from_world = np.eye(4)
        local_from_world[:3, 3] = -np.asarray(origin, dtype=np.float64)
        local_from_ndc = local_from_world @ w_c @ matrices.inverse(proj)
        forward = -w_c[:3, 2] / np.linalg.norm(w_c[:3, 2])
        return cls(np.ascontiguousarray(local_from_ndc), w_c[:3, 3] - np.asarray(origin, np.float64), forward)

    @classmethod
    def look_at(cls, eye, target, up=(0.0, 0.0, 1.0), fov_y: float = 40.0, aspect: float = 4 / 3,
                near: float = 1e-3, far: float = 1e4, ortho_height: Optional[float] = None) -> "Camera":
        """A camera at `eye` looking at `target`. Perspective with vertical field of view
        `fov_y` (degrees), or orthographic when `ortho_height` (the view's height) is given."""
        eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
        if not all(np.isfinite(v).all() and v.shape == (3,) for v in (eye, target, up)):
            raise ValueError("eye, target and up must be three finite numbers each")
        if ortho_height is None and not 0.0 < fov_y < 180.0:
            raise ValueError(f"fov_y must be between 0 and 180 degrees (exclusive), got {fov_y!r}")
        if ortho_height is not None and not (np.isfinite(ortho_height) and ortho_height > 0):
            raise ValueError(f"ortho_height must be a positive number, got {ortho_height!r}")
        if not (np.isfinite(aspect) and aspect > 0):
            raise ValueError(f"aspect must be a positive number, got {aspect!r}")
        if not (0.0 < near < far < np.inf):
            raise ValueError(f"need 0 < near < far (finite), got near={near!r}, far={far!r}")
        fwd = target - eye
        if not np.linalg.norm(fwd) > 0:
            raise ValueError("eye and target are the same point")
        fwd /= np.linalg.norm(fwd)
        right = np.cross(fwd, up)
        if np.linalg.norm(right) < 1e-12:
            raise ValueError("up is parallel to the view direction")
        right /= np.linalg.norm(right)
        cam_up = np.cross(right, fwd)
        w_c = np.eye(4)
        w_c[:3, 0], w_c[:3, 1], w_c[:3, 2], w_c[:3, 3] = right, cam_up, -fwd, eye
        proj = np.zeros((4, 4))
        if ortho_height is None:
            f = 1.0 / np.tan(np.radians(fov_y) / 2)
            proj[0, 0], proj[1, 1] = f / aspect, f
            proj[2, 2], proj[2, 3] = (far + near) / (near - far), 2 * far * near / (near - far)
            proj[3, 2] = -1.0
        else:
            proj[0, 0], proj[1, 1] = 2.0 / (ortho_height * aspect), 2.0 / ortho_height
            proj[2, 2], proj[2, 3] = -2.0 / (far - near), -(far + near) / (far - near)
            proj[3, 3] = 1.0
        return cls.from_view_projection(proj, w_c)

    def rays(self, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        """Pixel-centre rays (origins on the near plane, unit directions), row-major from
        the top row: the same rays `Scene.render` traces, for use with `Scene.trace`."""
        j, i = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
        ndc = np.stack([2 * j / width - 1, 1 - 2 * i / height], axis=-1).reshape(-1, 2)
        def unproject(z):
            p = matrices.transform_rows(np.column_stack([ndc, np.full(len(ndc), z), np.ones(len(ndc))]), self.local_from_ndc)
            return p[:, :3] / p[:, 3:]
        a, b = unproject(-1.0), unproject(1.0)
        d = b - a
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        return a.astype(np.float32), d.astype(np.float32)


class Scene:
    """Splats (oriented discs) and the BVH over them. Immutable; safe to share.

    centres (N,3), normals (N,3, any non-zero length), radii (N,) > 0 and optional colours
    (N,3, scene-linear RGB) in one local frame. closed: whether each splat belongs to a
    closed, hole-free object (bool for all, or (N,) flags; the far phase applies to those
    only). alphas: optional (N,) opacities in 0..1, the points' own alpha (a material whose
    Alpha reads them makes the cloud see-through there). Raises ValueError naming the first
    bad splat (non-finite value, zero normal, radius <= 0, alpha outside 0..1), TypeError for
    unusable arrays.
    threads: default thread count for tracing and rendering (0: all cores).
    """

    def __init__(self, centres, normals, radii, colours=None, closed=False, threads: int = 0, alphas=None):
        c = _f32(centres, "centres", (-1, 3))
        n = _f32(normals, "normals", (len(c), 3))
        r = _f32(radii, "radii", (len(c),))
        col = None if colours is None else _f32(colours, "colours", (len(c), 3))
        a = None if alphas is None else _f32(alphas, "alphas", (len(c),))
        flags = np.broadcast_to(np.asarray(closed, dtype=np.uint8), (len(c),))
        self._scene = _core.Scene(c, n, r, col, np.ascontiguousarray(flags), threads, a)

    def __len__(self) -> int:
        return self._scene.size

    @property
    def bounds(self):
        """((xmin, ymin, zmin), (xmax, ymax, zmax)) over every disc, or None when empty."""
        return self._scene.bounds

    def bvh_stats(self) -> dict:
        return self._scene.bvh_stats()

    def traversal_cost(self, origins, directions, tmin: float = 0.0, tmax: float = np.inf,
                       packets: bool = False) -> dict:
        """Work the BVH does for these nearest-hit rays: {'nodes': nodes entered, 'discs':
        disc tests}, summed over the rays. Tests compare costs with it instead of timings.
        packets: as in trace() (a packet's inner node counts once for all its rays)."""
        o = _f32(origins, "origins", (-1, 3))
        d = _f32(directions, "directions", (len(o), 3))
        n = len(o)
        stats = np.zeros(2, np.int64)
        self._scene.trace(o, d, float(tmin), float(tmax), np.empty(n, np.float32), np.empty(n, np.int32),
                          np.empty(n, np.bool_), None, 0, False, stats, packets)
        return {"nodes": int(stats[0]), "discs": int(stats[1])}

    def trace(self, origins, directions, tmin: float = 0.0, tmax: float = np.inf, normals: bool = True,
              threads: int = 0, brute_force: bool = False, packets: bool = True) -> TraceResult:
        """Nearest splat hit (either facing) per ray, in the open interval (tmin, tmax).

        Directions need not be unit length; they are normalised and `t` is a distance.
        brute_force tests every splat: the slow reference the BVH is checked against.
        packets: consecutive rays go through the tree 16 at a time when they are coherent
        (camera rays of a 4x4 pixel tile: order them so); False traces each ray alone. The
        answers are the same either way.
        """
        o = _f32(origins, "origins", (-1, 3))
        d = _f32(directions, "directions", (len(o), 3))
        n = len(o)
        t = np.empty(n, np.float32)
        ids = np.empty(n, np.int32)
        front = np.empty(n, np.bool_)
        nrm = np.empty((n, 3), np.float32) if normals else None
        self._scene.trace(o, d, float(tmin), float(tmax), t, ids, front, nrm, threads, brute_force, None, packets)
        return TraceResult(t, ids, front, nrm)

    def trace_surface(self, origins, directions, method: Method = Method(), tmin: float = 0.0,
                      tmax: float = np.inf, inside=None, exclude=None, members: bool = False,
                      threads: int = 0, brute_force: bool = False, packets: bool = True) -> SurfaceResult:
        """The surface each ray sees under `method`, with its shading normal and colour.

        inside: (N,) flags (or one bool) for rays travelling inside an object (refracted):
            their layer begins with a back-facing hit, the exit.
        exclude: (N, M) int32 splat ids each ray must not hit, -1 for none: a secondary ray
            (reflection, shadow, refraction) passes the `members` of the hit it starts from.
        members: also return the splats that made each surface point.
        brute_force: offer every splat to the query (the tests' reference for the BVH).
        packets: as in trace(); the first layer query of 16 coherent rays in one traversal.
        """
        o = _f32(origins, "origins", (-1, 3))
        d = _f32(directions, "directions", (len(o), 3))
        n = len(o)
        out = SurfaceResult(np.empty(n, np.float32), np.empty(n, np.int32), np.empty(n, np.bool_),
                            np.empty((n, 3), np.float32), np.empty((n, 3), np.float32),
                            np.empty((n, MAX_LAYER_HITS), np.int32) if members else None)
        inside_arr = None
        if inside is not None:
            inside_arr = np.ascontiguousarray(np.broadcast_to(np.asarray(inside, dtype=np.uint8), (n,)))
        ex = None
        if exclude is not None:
            raw = np.asarray(exclude)
            if raw.size and not np.issubdtype(raw.dtype, np.integer):
                raise TypeError(f"exclude must hold integer splat ids, got dtype {raw.dtype}")
            if raw.size and (raw.min() < -1 or raw.max() >= len(self)):
                raise ValueError(f"exclude holds ids outside -1..{len(self) - 1} (min {raw.min()}, max {raw.max()})")
            ex = np.ascontiguousarray(raw, dtype=np.int32)
            if ex.ndim != 2 or len(ex) != n:
                raise ValueError(f"exclude must have shape ({n}, M), got {ex.shape}")
        self._scene.trace_surface(o, d, float(tmin), float(tmax), method.as_tuple(), out.t, out.id, out.front,
                                  out.normal, out.colour, out.members, inside_arr, ex, threads, brute_force,
                                  packets)
        return out

    def render(self, camera: Camera, width: int, height: int, window: Optional[Sequence[int]] = None,
               background: Sequence[float] = (0.0, 0.0, 0.0, 0.0), depth: bool = True, normal: bool = True,
               threads: int = 0, progress: Optional[Callable[[int, int], bool]] = None,
               tile_size: int = 32, method: Method = Method(), packets: bool = True) -> RenderResult:
        """Renders one ray per pixel centre with a headlight, the surface chosen by `method`.

        window: (x0, y0, w, h) sub-rectangle of the width x height image (x0, y0: column
        and row of its top-left pixel), default the whole image. progress(done, total) is
        called from this thread every ~50 ms; returning True stops the render. packets:
        4x4 pixels traced as one packet (False: pixel by pixel; the same image).
        """
        x0, y0, w, h = _window(window, width, height)
        rgba = np.empty((h, w, 4), np.float32)
        dep = np.empty((h, w), np.float32) if depth else None
        nrm = np.empty((h, w, 3), np.float32) if normal else None
        done = self._scene.render(
            np.ascontiguousarray(camera.local_from_ndc, np.float64),
            np.ascontiguousarray(camera.position, np.float64),
            np.ascontiguousarray(camera.forward, np.float64),
            int(width), int(height), (int(x0), int(y0), int(w), int(h)),
            tuple(float(v) for v in background), rgba, dep, nrm, threads, progress, tile_size, method.as_tuple(),
            packets)
        return RenderResult(rgba, dep, nrm, done)


# --------------------------------------------------------------------------------------
# Scenes of several objects: meshes beside clouds, instances, materials, lamps, a world.

from .shading import (LIGHT_FIELDS, MATERIAL_FIELDS, PASSES, Light, Material,  # noqa: E402
                      RenderSettings, World)

SplatCloud = Scene  # a cloud is a Scene of splats; as geometry of a RenderScene it is this type

RAY_VISIBILITY = {"camera": 1, "diffuse": 2, "glossy": 4, "transmission": 8, "shadow": 16}


class Mesh:
    """A triangle mesh and its BVH: vertices (V,3), triangles (T,3) vertex indices, optional
    corner_normals (T,3,3) shading normals (smooth, flat and sharp edges as Blender's corner
    normals express them; None: flat) and material_index (T,) slots. Immutable; share one
    Mesh between any number of instances."""

    def __init__(self, vertices, triangles, corner_normals=None, material_index=None, threads: int = 0):
        v = _f32(vertices, "vertices", (-1, 3))
        t = np.asarray(triangles)
        if t.size and not np.issubdtype(t.dtype, np.integer):
            raise TypeError(f"triangles must hold integer vertex indices, got dtype {t.dtype}")
        if t.size and (t.min() < 0 or t.max() >= len(v)):
            raise ValueError(f"triangles index vertices outside 0..{len(v) - 1}")
        t = np.ascontiguousarray(t.reshape(-1, 3), dtype=np.int32)
        n = None if corner_normals is None else _f32(np.asarray(corner_normals).reshape(-1, 3, 3), "corner_normals",
                                                     (len(t), 3, 3))
        m = None if material_index is None else np.ascontiguousarray(material_index, dtype=np.int32)
        self._mesh = _core.Mesh(v, t, n, m, threads)

    def __len__(self) -> int:
        return self._mesh.size


@dataclass(frozen=True)
class Instance:
    """One placement of a geometry (a splat Scene or a Mesh) in the scene's local frame.

    matrix: 4x4 object-to-local transform (any affine: scale, shear, mirror). materials: the
    object's slots (a cloud uses the first). visibility: ray kinds that see it (keys of
    RAY_VISIBILITY; default all). holdout: camera rays that see it get alpha 0.
    pass_index: the Object Index pass value."""

    geometry: object
    matrix: tuple = ((1.0, 0.0, 0.0, 0.0), (0.0, 1.0, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0), (0.0, 0.0, 0.0, 1.0))
    materials: tuple = (Material(),)
    visibility: frozenset = frozenset(RAY_VISIBILITY)
    holdout: bool = False
    pass_index: int = 0


class FrameResult(NamedTuple):
    passes: dict      # pass name -> (h, w[, c]) float32 array, top row first
    completed: bool   # False when progress() asked to stop
    counters: dict    # rays traced by kind, and the queries' work


class RenderScene:
    """Instances of clouds and meshes with their materials, the lamps and the world: what a
    Blender frame is, for the core. Geometry is referenced, not copied: a hundred instances
    of one cloud cost one BVH. Build a new RenderScene when instances, materials or lamps
    change (cheap: only the top-level tree over the instances is built)."""

    def __init__(self, instances: Sequence[Instance], lights: Sequence[Light] = (), world: World = World(),
                 threads: int = 0):
        # Wrong types are refused here with a TypeError naming them, not left to fail later
        # as an AttributeError deep in pack() (or, for the world, only at render time).
        if not isinstance(world, World):
            raise TypeError(f"world must be a shading.World, got {type(world).__name__}")
        for light in lights:
            if not isinstance(light, Light):
                raise TypeError(f"lights must be shading.Light objects, got {type(light).__name__}")
        geometries, index_of = [], {}
        rows = []
        materials = []
        for inst in instances:
            if not isinstance(inst, Instance):
                raise TypeError(f"instances must be core.Instance objects, got {type(inst).__name__}")
            geo = inst.geometry
            native = geo._scene if isinstance(geo, Scene) else geo._mesh if isinstance(geo, Mesh) else None
            if native is None:
                raise TypeError(f"instance geometry must be a core.Scene or core.Mesh, got {type(geo).__name__}")
            if id(native) not in index_of:
                index_of[id(native)] = len(geometries)
                geometries.append(native)
            m = np.asarray(inst.matrix, np.float64).reshape(4, 4)
            if not np.isfinite(m).all() or abs(np.linalg.det(m[:3, :3])) < 1e-300:
                raise ValueError("instance matrix must be finite and invertible")
            inv = matrices.inverse(m)
            unknown = set(inst.visibility) - set(RAY_VISIBILITY)
            if unknown:
                raise ValueError(f"unknown ray visibility {sorted(unknown)}; use {sorted(RAY_VISIBILITY)}")
            mats = tuple(inst.materials) or (Material(),)
            for mat in mats:
                if not isinstance(mat, Material):
                    raise TypeError(f"instance materials must be shading.Material objects, got {type(mat).__name__}")
            rows.append((index_of[id(native)], m[:3].ravel(), inv[:3].ravel(), (len(materials), len(mats)),
                         sum(RAY_VISIBILITY[k] for k in inst.visibility), inst.holdout, inst.pass_index))
            materials.extend(mats)
        n = len(rows)
        col = lambda k, dtype: np.array([r[k] for r in rows], dtype).reshape((n,) + np.shape(rows[0][k]) if n else (0,))
        self.world = world
        self.lights = tuple(lights)
        self._scene = _core.RenderScene(
            geometries,
            np.ascontiguousarray(col(0, np.int32)),
            np.ascontiguousarray(col(1, np.float32).reshape(n, 12)),
            np.ascontiguousarray(col(2, np.float32).reshape(n, 12)),
            np.ascontiguousarray(col(3, np.int32).reshape(n, 2)),
            np.ascontiguousarray(col(4, np.int32)),
            np.ascontiguousarray(col(5, np.uint8)),
            np.ascontiguousarray(col(6, np.float32)),
            np.ascontiguousarray(np.array([m.pack() for m in materials], np.float32).reshape(-1, len(MATERIAL_FIELDS))),
            np.ascontiguousarray(np.array([l.pack() for l in lights], np.float32).reshape(-1, len(LIGHT_FIELDS))),
            threads)
        self.geometry_count = len(geometries)

    def render(self, camera: Camera, width: int, height: int, settings: RenderSettings = RenderSettings(),
               method: Method = Method(), passes: Sequence[str] = ("Combined",),
               window: Optional[Sequence[int]] = None, threads: int = 0,
               progress: Optional[Callable[[int, int], bool]] = None, tile_size: int = 32,
               packets: bool = True) -> FrameResult:
        """Renders `passes` (names from shading.PASSES; Combined always) of a window of the
        image (x0, y0, w, h; default all). progress(done, total) as for Scene.render.
        packets: each sample's camera rays of 4x4 pixels found as one packet (False: ray by
        ray; the same image)."""
        for value, kind, name in ((camera, Camera, "camera"), (settings, RenderSettings, "settings"),
                                  (method, Method, "method")):
            if not isinstance(value, kind):
                raise TypeError(f"{name} must be a {kind.__name__}, got {type(value).__name__}")
        if isinstance(passes, str):
            raise TypeError("passes must be a sequence of pass names, not one string")
        unknown = set(passes) - set(PASSES)
        if unknown:
            raise ValueError(f"unknown passes {sorted(unknown)}; known: {sorted(PASSES)}")
        x0, y0, w, h = _window(window, width, height)
        buffers = {}
        for name in ("Combined", *passes):
            c = PASSES[name]
            buffers[name] = np.zeros((h, w) if c == 1 else (h, w, c), np.float32)
        key = {"Depth": "depth", "Normal": "normal", "DiffCol": "diffcol", "Emit": "emit", "Shadow": "shadow",
               "IndexOB": "index", "Splat Count": "splat_count"}
        optional = {key[name]: buf for name, buf in buffers.items() if name != "Combined"}
        done, counters = self._scene.render(
            np.ascontiguousarray(camera.local_from_ndc, np.float64), np.ascontiguousarray(camera.position, np.float64),
            np.ascontiguousarray(camera.forward, np.float64), int(width), int(height),
            (int(x0), int(y0), int(w), int(h)), settings.pack(), method.as_tuple(), self.world.radiance(),
            bool(self.world.transparent), buffers["Combined"], threads=threads, progress=progress,
            tile_size=tile_size, packets=packets, **optional)
        return FrameResult(buffers, bool(done), counters)
