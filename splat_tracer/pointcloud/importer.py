"""The import pipeline without Blender: memory check, read, axes and scale, point budget,
preparation (prepare.py). The operator runs it (on a worker thread in the UI) and only then
creates Blender data, so that an error or a cancel leaves nothing half-made.

- Axes and scale (`ImportOptions.axes`, `.scale`): the file's coordinates are turned into
  Blender's by an orthonormal 3x3 matrix (bpy_extras.io_utils.axis_conversion: a signed
  permutation, applied exactly in float64) and multiplied by the scale, all in float64
  before anything becomes float32; normals and scanner positions turn with them, radii are
  scaled. The origin (prepare.py) is then taken in the converted frame, so the object sits
  at the converted georeference and the float32 offsets keep their precision.
- Point budget (`ImportOptions.max_points`): a cloud with more points is thinned to exactly
  that many, evenly over space, deterministically: a grid whose cell is chosen so that at
  least `max_points` cells are occupied keeps the point nearest each cell's centre (dense
  parts lose more points than sparse ones), and a fixed-seed random choice among those cells
  makes up the exact count.
- Memory: the points a file declares (PLY, LAS/LAZ, E57, PCD headers) are checked against the
  available memory before anything is read (BYTES_PER_POINT_*).
"""
from __future__ import annotations

import os
from dataclasses import dataclass, replace
from typing import Optional

import numpy as np

from ..util import matrices, resources
from ..util.columns import bounds
from ..util.progress import ProgressFn, nothing, scaled
from . import normals, prepare, readers, spacing
from .cloud import MAX_RADIUS, CloudFileError, PointCloud, shared_row
from .readers.e57 import check_structure as check_e57_structure
from .readers.las import read_header as read_las_header
from .readers.pcd import NORMAL_FIELDS, read_header as read_pcd_header
from .readers.ply import read_header

# Peak memory of an import per point, measured by benchmarks/import_speed.py at 10M points
# (peak RSS above the process's RSS before the import, Blender object included): 78 bytes
# for a PLY with normals (float32 coordinates) and 92 for a LAS given normals (positions in
# float64, colours, attributes, the k-d tree, the float32 offsets handed to Blender, each
# array let go of as Blender copies it), 214 for a LAS whose normals are estimated; the
# extra for estimating normals and orienting them along the neighbour graph was 231 bytes on
# top of the positions (the graph's 8 edges per point, the renumbered copies, the spanning
# forest). The budgets below were set from earlier, larger figures (210-223 and 275 bytes)
# and are kept: headroom (a PLY with float64 coordinates, a file with more attributes), not
# a measurement.
BYTES_PER_POINT_READ = 300
BYTES_PER_POINT_NORMALS = 350
# The budget's grid: at most this many refinements of the cell size (each one sort of the
# cells' keys); a surface's occupied cells grow with 1/cell^2, so two or three suffice.
BUDGET_ITERATIONS = 8
# Accept a grid once it has at most this many times the budget's cells: the random choice
# among them then leaves out at most a sixth of the cells, which keeps the subset even.
BUDGET_SLACK = 1.2
BUDGET_SEED = 0  # the fixed seed of the budget's random choice: the same file gives the same points
_KEY_BITS = 21   # bits per axis of a cell's key (3 x 21 fit an int64)


@dataclass
class ImportOptions:
    k: int = spacing.DEFAULT_K            # radius neighbours
    drop_outliers: bool = False           # gross outliers (prepare.OUTLIER_REACH) left out
    normal_k: int = normals.DEFAULT_K
    orientation: str = "AUTO"
    columns: str = ""                     # text files' column mapping (readers.read_text)
    axes: Optional[np.ndarray] = None     # (3,3) orthonormal: file coordinates -> Blender's; None: as they are
    scale: float = 1.0
    max_points: int = 0                   # the point budget; 0: every point
    statistical_ratio: float = 0.0        # > 0: statistical outlier removal with this many std deviations
    hole_free: bool = True                # k-NN radii raised to close gaps (spacing.covering_radii)
    workers: int = -1


def transform(cloud: PointCloud, axes=None, scale: float = 1.0) -> PointCloud:
    """The cloud in Blender's axes and units (see the module's text)."""
    if not (np.isfinite(scale) and scale > 0):
        raise ValueError(f"the scale must be a positive number, got {scale!r}")
    if axes is None and scale == 1.0:
        return cloud
    m = np.eye(3) if axes is None else np.asarray(axes, dtype=np.float64).reshape(3, 3)
    if not np.allclose(m @ m.T, np.eye(3), atol=1e-6):
        raise ValueError("the axis conversion must be orthonormal (a rotation or a reflection)")
    if np.allclose(m, np.round(m), atol=1e-6):
        m = np.round(m)  # a signed permutation (every axis_conversion): exact in float64
    pos = matrices.transform_rows(cloud.positions, m)
    if scale != 1.0:
        pos *= scale
    turn = (lambda a: None if a is None else matrices.transform_rows(a, m).astype(a.dtype))  # noqa: E731
    scanners, shared = cloud.scanners, shared_row(cloud.scanners)
    if shared is not None:  # one sensor: its row alone turned
        scanners = np.broadcast_to(matrices.transform_rows(shared[None], m)[0] * scale, scanners.shape)
    elif scanners is not None:
        scanners = matrices.transform_rows(scanners, m) * scale
    radii = None if cloud.radii is None else (cloud.radii * np.float32(scale)).astype(np.float32)
    out = replace(cloud, positions=pos, normals=turn(cloud.normals), scanners=scanners, radii=radii)
    if radii is not None and scale > 1.0:
        # The reader dropped radii beyond the renderer's limit (make_cloud); the scale can
        # carry more past it, and those points are dropped and counted alike.
        huge = ~(radii <= MAX_RADIUS)
        if huge.any():
            out = replace(out.subset(~huge), dropped_radii=cloud.dropped_radii + int(huge.sum()))
    return out


def _cell_keys(points: np.ndarray, lo: np.ndarray, cell: float) -> Optional[np.ndarray]:
    """(N,) int64 key of each point's grid cell, or None when the grid is too fine to key."""
    idx = np.floor((points - lo) / cell)
    if idx.max() >= 2 ** _KEY_BITS:
        return None
    idx = idx.astype(np.int64)
    return (idx[:, 0] << (2 * _KEY_BITS)) | (idx[:, 1] << _KEY_BITS) | idx[:, 2]


def even_subset(points: np.ndarray, budget: int, progress: Optional[ProgressFn] = None) -> np.ndarray:
    """Sorted indices of `budget` points spread evenly over the cloud (see the module's
    text); all of them when there are no more than `budget`."""
    report = progress or nothing
    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    if budget <= 0 or n <= budget:
        return np.arange(n)
    rng = np.random.default_rng(BUDGET_SEED)
    lo, hi = bounds(pts)
    extent = hi - lo
    # First guess: a surface through the box (its two largest sides) sampled by `budget` cells.
    sides = np.sort(extent)[1:]
    cell = float(np.sqrt(max(sides[0] * sides[1], sides[1] ** 2 / budget, 1e-300) / budget))
    best = None  # (cell, keys, occupied) of the coarsest grid with at least `budget` cells
    for i in range(BUDGET_ITERATIONS):
        report(i / BUDGET_ITERATIONS, "point budget: grid")
        keys = _cell_keys(pts, lo, cell)
        if keys is None:  # finer than 2^21 cells along an axis: plain random choice
            break
        occupied = len(np.unique(keys))
        if occupied >= budget:
            best = (cell, keys, occupied)
            if occupied <= BUDGET_SLACK * budget:
                break
        # occupied cells of a surface ~ 1/cell^2; aim a little above the budget
        cell *= float(np.clip(np.sqrt(occupied / (1.1 * budget)), 0.25, 4.0))
    if best is None:
        return np.sort(rng.choice(n, budget, replace=False))
    cell, keys, _ = best
    report(0.9, "point budget: one point per cell")
    centre_offset = (pts - lo) / cell
    centre_offset -= np.floor(centre_offset) + 0.5
    dist = np.einsum("ij,ij->i", centre_offset, centre_offset)
    order = np.lexsort((dist, keys))  # by cell, nearest the centre first
    sorted_keys = keys[order]
    picked = order[np.r_[True, sorted_keys[1:] != sorted_keys[:-1]]]
    if len(picked) > budget:
        picked = rng.choice(picked, budget, replace=False)
    return np.sort(picked)


def apply_budget(cloud: PointCloud, budget: int, progress: Optional[ProgressFn] = None) -> PointCloud:
    """The cloud thinned to at most `budget` points (even_subset), with a note saying so."""
    n = len(cloud)
    if budget <= 0 or n <= budget:
        return cloud
    keep = even_subset(cloud.positions, budget, progress)
    thinned = cloud.subset(keep)
    note = (f"point budget {budget:,}: {n - len(keep):,} of {n:,} points were left out (evenly over space, "
            "the same points on every import)")
    return replace(thinned, notes=list(cloud.notes) + [note], budget_dropped=n - len(keep))


def declared_points(path: str, kind: str) -> Optional[int]:
    """The points the file's header declares (PLY, LAS/LAZ, E57, PCD), None for text (whose size
    bounds what reading it allocates) or when the header cannot tell (the reader will say why)."""
    try:
        if kind == "PLY":
            _, header = read_header(path)
            return sum(e.count for e in header.elements if e.name == "vertex")
        if kind == "LAS":  # its own header check: laspy.open loops on a corrupt count of VLRs
            return read_las_header(path).point_count
        if kind == "PCD":
            return read_pcd_header(path).metadata.points
        if kind == "E57":  # its own structure check: pye57 crashes on a scan without a prototype
            check_e57_structure(path)
            import pye57

            e57 = pye57.E57(path)
            try:
                return sum(int(e57.get_header(i).point_count) for i in range(e57.scan_count))
            finally:
                e57.close()
    except CloudFileError:
        raise
    except Exception:  # a broken header: the reader refuses it with its own message
        return None
    return None


def check_memory(path: str, kind: str, options: ImportOptions, estimates_normals: bool = True) -> None:
    """Refuses, before reading, a file whose declared points cannot fit in the memory available."""
    n = declared_points(path, kind)
    free = resources.available_memory()
    if not n or free is None:
        return
    kept = min(n, options.max_points) if options.max_points > 0 else n
    needed = n * BYTES_PER_POINT_READ + (kept * BYTES_PER_POINT_NORMALS if estimates_normals else 0)
    if needed > free * (1.0 - resources.HEADROOM):
        raise CloudFileError(
            f"{path}: declares {n:,} points; importing them needs about {needed / 2**30:.1f} GB of memory but only "
            f"{free / 2**30:.1f} GB are available (refused before reading; free memory, set a lower Point Budget, "
            "or split the file)")


def load(path: str, options: Optional[ImportOptions] = None, progress: Optional[ProgressFn] = None
         ) -> prepare.PreparedCloud:
    """Reads and prepares one file. Raises CloudFileError naming the file, or Cancelled
    (from `progress`); creates nothing either way."""
    options = options or ImportOptions()
    report = progress or nothing
    path = os.fspath(path)
    name = os.path.basename(path)
    kind = readers.sniff(path)
    # Only PLY and PCD can say from their headers whether normals follow; assume the worst elsewhere.
    check_memory(path, kind, options, estimates_normals=not _has_normals(path, kind))
    report(0.0, f"reading {name}")
    cloud = readers.read_cloud(path, options.columns, scaled(progress, 0.0, 0.2, f"{name}: "))
    report(0.2, f"read {len(cloud):,} points")
    try:
        cloud = transform(cloud, options.axes, options.scale)
    except ValueError as e:
        raise CloudFileError(f"{path}: {e}") from None
    cloud = apply_budget(cloud, options.max_points, scaled(progress, 0.2, 0.25))
    # Handed over, not kept here: prepare lets go of the float64 positions once it has the
    # float32 offsets (a called Python function owns its arguments in CPython 3.11+, the
    # caller's frame keeps no reference to a value it did not name).
    handed = [cloud]
    del cloud
    prepared = prepare.prepare(handed.pop(), path, options.k, options.drop_outliers, options.workers, options.normal_k,
                               options.orientation, options.statistical_ratio, scaled(progress, 0.25, 1.0),
                               options.hole_free)
    report(1.0, f"prepared {len(prepared.local):,} splats")
    return prepared


def _has_normals(path: str, kind: str) -> bool:
    """Whether the file's header says it has normals (PLY, PCD; False for the others)."""
    try:
        if kind == "PLY":
            _, header = read_header(path)
            names = {p.name for e in header.elements if e.name == "vertex" for p in e.properties}
            return {"nx", "ny", "nz"} <= names
        if kind == "PCD":
            return set(NORMAL_FIELDS) <= set(read_pcd_header(path).metadata.fields)
    except CloudFileError:
        return False
    return False


def load_many(paths, options: Optional[ImportOptions] = None, progress: Optional[ProgressFn] = None) -> list:
    """[(path, PreparedCloud)] for every file, each given an equal share of the progress;
    the first bad file (CloudFileError) or a cancel stops it all."""
    paths = list(paths)
    out = []
    for i, path in enumerate(paths):
        prefix = f"{os.path.basename(path)} ({i + 1}/{len(paths)}): " if len(paths) > 1 else ""
        out.append((path, load(path, options, scaled(progress, i / len(paths), (i + 1) / len(paths), prefix))))
    return out
