"""From a cloud read from a file to what the importer stores (no Blender needed).

The bulk of a scan decides the frame and the analysis, never a few stray points: scanners
write invalid returns as (0, 0, 0) into georeferenced scans, and one such point would
move the origin halfway to it, degrade every other point's float32 offset, flip the
closed guess and get a disc millions of metres wide.

- Outliers: the bulk's size is the largest side of the box between the 1st and 99th
  percentiles of the coordinates (a robust spread: up to 1 % of the points on each side
  cannot widen it). A point more than OUTLIER_REACH such sizes outside that box is an
  outlier. They are kept by default (a point is never lost silently) or dropped on request,
  and reported either way (count and first file row).
- The origin is the centre of the bulk's bounding box (local_frame with the inliers).
- The neighbourhood analysis (k-NN spacing, closed guess) runs on the inliers; a kept
  outlier's spacing is its k-NN distance among all points.
- k-NN radii are clamped to RADIUS_CAP times the 95th percentile of the inliers' spacing,
  so that an isolated point never becomes a giant disc; the clamped radii are counted.
- Precision: every point is stored as a float32 offset from the one origin, so a cloud that
  spans much more than its spacing (two cm-spaced clusters 1e7 m apart) has its points moved
  by the rounding. The points moved by more than PRECISION_FRACTION of their radius are
  counted and the cause named in the notes (they are kept: the import cannot split a cloud
  into objects).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Optional

import numpy as np

from ..util.columns import bounds, rows_outside
from ..util.progress import Steps, scaled
from . import normals as normals_mod, spacing
from .cloud import MAX_RADIUS, CloudFileError, PointCloud, shared_row
from .neighbours import local_frame

# The bulk's box: 1 % of the points on each side may lie anywhere without moving it.
BULK_PERCENTILES = (1.0, 99.0)
# Larger clouds take the percentiles from this many points drawn at random (fixed seed,
# with replacement: drawing without it permutes all N indices, 80 MB of fresh memory at 10M
# points): a percentile of 200k samples is within about 0.02 % of the points of the true
# one (its rank's standard deviation, sqrt(0.01 x 0.99 / 200k)), and the outlier rule
# (OUTLIER_REACH bulk sizes away) does not notice; at 10M points the full percentiles cost
# a second, and 1M samples 0.15 s.
BULK_SAMPLE = 200_000
# How many bulk sizes outside the bulk's box a point must lie to be an outlier. Genuine
# sparse parts of a scan (a terrestrial scanner's far returns, a driveway leaving a
# building) reach a few bulk sizes; a stray (0, 0, 0) in a georeferenced scan lies 1e3 to
# 1e6 bulk sizes away. 10 keeps the former and finds the latter.
OUTLIER_REACH = 10.0
# k-NN radii are at most RADIUS_CAP x the 95th percentile of the bulk's spacing. On an
# evenly sampled surface the spacing varies by tens of percent, and a scan's sparse parts
# are within the top 5 %: a radius 3 times beyond that (a disc 9+ times the area of the
# sparsest 5 %'s) has no neighbours to overlap; it only makes a blob that hides the surface
# behind it. Smaller radii are left alone: a small disc among its neighbours' is harmless.
RADIUS_CAP_PERCENTILE = 95.0
RADIUS_CAP = 3.0
# The local cap (local_cap): a disc at most LOCAL_CAP x the median radius of its LOCAL_K
# nearest. In a sparse region (water in airborne LiDAR, a terrestrial scan's far returns)
# neighbours are sparse alike and keep their gap-closing discs; a point far from its few
# neighbours (the 6th of which may lie across the water) would otherwise get a coin many
# times theirs that floats over them. Only discs above LOCAL_FROM x the median radius are
# looked at (a search of their own: few points, a few ms); smaller ones cannot be coins.
LOCAL_K = 8
LOCAL_CAP = 2.0
LOCAL_FROM = 2.0
# The largest coordinate and extent a cloud may have. Points are stored as float32 offsets
# from a float32 origin, and the renderer squares distances in float32 (and sums squares,
# and multiplies areas by counts in the BVH's cost), whose range ends at 3.4e38: offsets
# up to 1e15 square to 1e30, eight orders of magnitude below that. Georeferenced scans
# are within 1e7 (metres) or 1e10 (millimetres); beyond 1e15 a file holds garbage.
MAX_COORDINATE = 1e15
# A point lost precision when float32 rounding moved it by more than this fraction of its
# splat radius: its disc then visibly leaves its place among its neighbours' (a fifth of it
# shows as a gap or overlap at a disc's rim). A single cluster recentred by local_frame never
# comes near it (its offsets' float32 steps are 6e-8 of its extent); two clusters far apart
# stored from one origin do (1 m steps at 1e7 m, against cm spacing).
PRECISION_FRACTION = 0.1


@dataclass
class PreparedCloud:
    cloud: PointCloud                  # the points imported (outliers removed when dropped)
    origin: np.ndarray                 # (3,) float64 holding a float32 value: the object's location
    local: np.ndarray                  # (N,3) float32 offsets from the origin
    radii: np.ndarray                  # (N,) float32: the file's, else clamped k-NN spacing
    hood: spacing.Neighbourhood        # the analysis of the bulk (inliers)
    outliers: int = 0                  # points far from the bulk (found; imported unless dropped)
    first_outlier_row: int = -1        # the first of them, as a row of the file
    outliers_dropped: bool = False
    clamped_radii: int = 0             # k-NN radii reduced to radius_cap
    locally_capped: int = 0            # radii reduced to LOCAL_CAP x their neighbours' (local_cap)
    radius_cap: float = 0.0
    normals_estimated: bool = False    # the file had none: PCA over normal_k neighbours
    normals_oriented: str = ""         # the rule that decided the signs when the import chose them (normals.py)
    orientation_evidence: str = ""     # why AUTO chose that rule
    oriented_by_rule: float = 0.0      # the share of points whose sign the rule decided; the rest by propagation
    ambiguous: int = 0                 # points whose orientation was ambiguous
    normal_k: int = 0
    slivers: int = 0                   # estimated normals replaced by their neighbours' consensus (normals.fix_slivers)
    quantised: str = ""                # the depth quantisation found (normals.quantised_depth), in words
    adaptive: Optional[dict] = None    # neighbourhood reach -> normals fitted over it (normals.adaptive_normals)
    statistical_outliers: int = 0      # points left out by statistical outlier removal
    statistical_ratio: float = 0.0
    lost_precision: int = 0            # points float32 rounding moved by more than PRECISION_FRACTION x their radius
    precision_error: float = 0.0       # the largest such move
    precision_step: float = 0.0        # float32's step at the farthest of them from the origin
    extent: float = 0.0                # the largest side of the cloud's bounding box

    def notes(self, k: int) -> list[str]:
        """What the import changed or found, one sentence each (the import's warnings)."""
        c = self.cloud
        notes = list(c.notes)
        if c.dropped_rows:
            notes.append(f"{c.dropped_rows:,} rows with non-finite coordinates were dropped")
        if self.normals_oriented:
            how = f"oriented {_ORIENTED[self.normals_oriented]}"
            if self.orientation_evidence:
                # PROPAGATE with evidence: AUTO's rules were tried, and the graph decided alone.
                how += (f", after {self.orientation_evidence}" if self.normals_oriented == "PROPAGATE"
                        else f" (decided by {self.orientation_evidence})")
            if self.normals_oriented in ("SCANNER", "ORIGIN", "UP"):
                how += f"; {self.oriented_by_rule:.1%} of the points by that rule"
                if self.oriented_by_rule < 1.0:
                    how += ", the rest from their neighbours"
            if self.normals_estimated:
                notes.append(f"the file has no normals: estimated from the {self.normal_k} nearest neighbours, {how}")
            else:
                notes.append(f"the file's normal axes have no sign ({c.format}): {how}")
        if self.adaptive:
            sizes = ", ".join(f"{count:,} over {reach:,}" for reach, count in sorted(self.adaptive.items()))
            notes.append(f"depth quantisation found ({self.quantised}): normals fitted over neighbourhoods wide "
                         f"enough to span {normals_mod.QUANT_SPAN:g} depth steps (points over neighbours' reach: "
                         f"{sizes})")
        if self.slivers:
            notes.append(f"{self.slivers:,} estimated normals were more than {normals_mod.SLIVER_ANGLE:g} degrees off "
                         "their neighbours' (slivers from noise): given their neighbours' consensus normal")
        if self.ambiguous:
            notes.append(f"{self.ambiguous:,} points' normal orientation was ambiguous (a neighbour more than 60 "
                         "degrees off, or a grazing view); check them, or re-estimate with another orientation")
        if c.dropped_radii:
            notes.append(f"{c.dropped_radii:,} points with a radius beyond the renderer's limit ({MAX_RADIUS:.0e}) "
                         "were dropped")
        if c.dropped_normals:
            notes.append(f"{c.dropped_normals:,} points with a zero or non-finite normal were dropped")
        if c.merged_duplicates:
            notes.append(f"{c.merged_duplicates:,} points repeat the position of an earlier one and were merged "
                         f"into it (first: row {c.first_duplicate_row})")
        if self.outliers:
            notes.append(f"{self.outliers:,} point{'s lie' if self.outliers != 1 else ' lies'} far from the rest "
                         f"(more than {OUTLIER_REACH:g} times the bulk's size outside it; first: row "
                         f"{self.first_outlier_row}); "
                         + ("dropped" if self.outliers_dropped else "kept (import with Outliers: Drop to leave "
                                                                     "them out)"))
        if self.statistical_outliers:
            notes.append(f"{self.statistical_outliers:,} points were left out by statistical outlier removal (mean "
                         f"distance to their {spacing.SOR_K} nearest neighbours more than {self.statistical_ratio:g} "
                         "standard deviations above the cloud's mean)")
        if self.clamped_radii:
            notes.append(f"{self.clamped_radii:,} splat radii were reduced to {self.radius_cap:.4g} "
                         f"({RADIUS_CAP:g} x the {RADIUS_CAP_PERCENTILE:g}th percentile of the spacing): "
                         "their points have no close neighbours")
        if self.locally_capped:
            notes.append(f"{self.locally_capped:,} splat radii were reduced to {LOCAL_CAP:g} x the median radius of "
                         f"their {LOCAL_K} nearest neighbours: their points lie far from those (a sparse region)")
        if self.lost_precision:
            notes.append(f"{self.lost_precision:,} points lost precision: the points span {self.extent:.2g} but are "
                         f"{np.median(self.hood.spacing):.2g} apart, and float32 offsets from one origin cannot hold "
                         f"both (steps of {self.precision_step:.2g} that far from it; points moved by up to "
                         f"{self.precision_error:.2g}); import the clusters as separate files, or crop")
        if self.hood.degenerate and c.radii is None:
            notes.append(f"{self.hood.degenerate} points share their position with {k}+ others"
                         + (" after that rounding" if self.lost_precision else "") + "; they got the median radius")
        return notes


_ORIENTED = {"PROPAGATE": "consistently along the neighbour graph (outward where the surface encloses a volume)",
             "UP": "upward (+Z)", "SCANNER": "towards the scanner positions",
             "ORIGIN": "towards the file's origin (the sensor of a single view)",
             "VISIBILITY": "towards the side from which the surface is seen, then along the neighbour graph",
             "": ""}


def resolve_orientation(orientation: str, scanners: bool, viewpoint: bool = True) -> str:
    """The orientation mode asked of normals.orient: SCANNER without scanners, or ORIGIN
    without the file's origin, is PROPAGATE. AUTO stays AUTO: normals.orient takes the
    scanners when they are known (E57 poses, a PCD's viewpoint), else decides from the
    geometry, whatever the format (a LAS file may hold an object)."""
    if (orientation == "SCANNER" and not scanners) or (orientation == "ORIGIN" and not viewpoint):
        orientation = "PROPAGATE"
    return orientation


def bulk_mask(positions: np.ndarray) -> np.ndarray:
    """(N,) bool: True for the points that are not outliers (see the module's text)."""
    pos = np.asarray(positions)  # float64, or a float32 file's coordinates (compared in float64 below)
    with np.errstate(over="ignore", invalid="ignore"):  # coordinates near 1e308: no bulk, no outliers
        sample = pos
        if len(pos) > BULK_SAMPLE:  # percentiles of a seeded sample: the same box, to 1e-3 of the bulk's size
            sample = pos[np.random.default_rng(0).integers(0, len(pos), BULK_SAMPLE)]
        lo, hi = np.percentile(np.asarray(sample, np.float64), BULK_PERCENTILES, axis=0)
        size = float(np.max(hi - lo))
        # Percentiles of coordinates near +-1.8e308 can overflow to +-inf or NaN on some axis
        # while another axis gives a finite size: then every point "lay outside" the bulk and
        # prepare() failed with a raw numpy error (found by fuzz/fuzz_prepare.py). No bulk then.
        if not (np.isfinite(lo).all() and np.isfinite(hi).all() and np.isfinite(size) and size > 0):
            return np.ones(len(pos), bool)
        reach = OUTLIER_REACH * size
        return ~rows_outside(pos, lo - reach, hi + reach)


def _span(positions: np.ndarray) -> tuple[float, float, float]:
    """(largest side of the bounding box, smallest coordinate, largest coordinate)."""
    lo, hi = bounds(positions)
    with np.errstate(over="ignore"):  # sides of boxes near 1e308 are inf: too large anyway
        return float(np.max(hi - lo)), float(lo.min()), float(hi.max())


def _check_float32_safe(positions: np.ndarray, bulk: np.ndarray, path: str) -> float:
    """The cloud's extent (the largest side of its bounding box), when float32 offsets can hold it."""
    extent, lo, hi = _span(positions)
    if extent <= MAX_COORDINATE and max(-lo, hi) <= MAX_COORDINATE:
        return extent
    hint = ""
    if not bulk.all() and bulk.any():
        b_extent, b_lo, b_hi = _span(positions[bulk])
        if b_extent <= MAX_COORDINATE and max(-b_lo, b_hi) <= MAX_COORDINATE:
            hint = (f"; without its {int((~bulk).sum()):,} outlier(s) it would fit: import with "
                    "Outliers: Drop")
    raise CloudFileError(
        f"{path}: the cloud spans {extent:.3g} (coordinates from {lo:.3g} to {hi:.3g}); coordinates and "
        f"extents beyond {MAX_COORDINATE:.0e} cannot be stored safely as float32 offsets from the import "
        f"origin (the renderer squares them in float32, whose range ends at 3.4e38){hint}")


def local_cap(radii: np.ndarray, tree, rows=None) -> int:
    """Reduces, in place, each radius above LOCAL_FROM x the median radius to at most LOCAL_CAP
    x the median radius of its LOCAL_K nearest neighbours (see LOCAL_CAP); returns how many.
    tree: a neighbour_tree of the points `rows` of radii (None: all of them); the others (kept
    outliers) keep their radii."""
    sub = radii if rows is None else radii[rows]
    k = min(LOCAL_K, len(sub) - 1)
    big = np.flatnonzero(sub > LOCAL_FROM * np.median(sub))
    if k < 1 or not len(big):
        return 0
    _, ids = tree.knn(big, k)
    # Against the neighbours' radii as they were: a capped disc does not shrink the next one's cap.
    limit = (LOCAL_CAP * np.median(sub[ids], axis=1)).astype(np.float32)
    over = sub[big] > limit
    sub[big[over]] = limit[over]
    if rows is not None:
        radii[rows] = sub
    return int(over.sum())


def _subset(cloud: PointCloud, keep: np.ndarray) -> PointCloud:
    return cloud.subset(keep)


def prepare(cloud: PointCloud, path: str, k: int = spacing.DEFAULT_K, drop_outliers: bool = False,
            workers: int = -1, normal_k: int = normals_mod.DEFAULT_K, orientation: str = "AUTO",
            statistical_ratio: float = 0.0, progress=None, hole_free: bool = True) -> PreparedCloud:
    """Frame, outliers, normals (estimated and oriented when the file has none; oriented
    when their signs are arbitrary), analysis and radii of a cloud; raises CloudFileError
    naming `path`. orientation: one of normals.MODES (normals.py).
    statistical_ratio > 0: statistical outlier removal with that many standard deviations
    (spacing.statistical_inliers). progress: progress.ProgressFn (it may raise Cancelled).
    hole_free: k-NN radii raised where gaps between samples would show (spacing.covering_radii)."""
    if len(cloud) < spacing.MIN_POINTS:  # refused before the neighbour search, which needs them
        usable = len(cloud) + cloud.merged_duplicates
        raise CloudFileError(
            f"{path}: only {len(cloud)} distinct position{'s' if len(cloud) != 1 else ''} among its {usable:,} "
            f"usable points ({cloud.merged_duplicates:,} repeat an earlier one); at least {spacing.MIN_POINTS} "
            "are needed to size the splats")
    bulk = bulk_mask(cloud.positions)
    outliers = int(len(bulk) - bulk.sum())
    first_outlier = -1
    if outliers:  # as a row of the file
        first_outlier = int(np.argmin(bulk) if cloud.rows is None else cloud.rows[np.argmin(bulk)])
    if outliers and drop_outliers:
        cloud, bulk = _subset(cloud, bulk), np.ones(int(bulk.sum()), bool)
    needs_normals = cloud.normals is None or not cloud.oriented
    # Shares of the progress bar, roughly as the steps' times at 1M-10M points: the normals'
    # estimation about twice its orientation; the radii (spacing and gap-closing radii from
    # one search) as much as the estimation when they need their own search (the file has
    # normals), a fifth of it (the closed guess's sample) when they reuse the estimation's.
    estimating = cloud.normals is None
    weights = {"statistical": 1.0 if statistical_ratio > 0 else 0.0, "estimate": 2.0 if estimating else 0.0,
               "orient": 1.0 if needs_normals else 0.0, "radii": 0.4 if estimating else 2.0}
    step = Steps(progress, weights)
    statistical = 0
    if statistical_ratio > 0 and len(cloud) > spacing.MIN_POINTS:
        keep = spacing.statistical_inliers(cloud.positions, statistical_ratio, workers=workers,
                                           progress=step("statistical"))
        statistical = int(len(keep) - keep.sum())
        if statistical:
            cloud, bulk = _subset(cloud, keep), bulk[keep]
    extent = _check_float32_safe(cloud.positions, bulk, path)
    rounding = np.empty(len(cloud), np.float32)  # how far float32 moved each point (local_frame fills it)
    origin, local = local_frame(cloud.positions, bulk, rounding)
    if needs_normals and cloud.normals is None and len(cloud) < normals_mod.MIN_POINTS:
        raise CloudFileError(f"{path}: has no normals (nx, ny, nz) and only {len(cloud)} distinct points, too "
                             f"few to estimate them (at least {normals_mod.MIN_POINTS} are needed)")
    rel = cloud.positions - origin if needs_normals else None  # float64 offsets: the estimation's precision is the file's
    # The float64 positions are not needed any more (origin + local hold them): without them
    # the k-d tree's memory comes from their pages instead of fresh ones (when the caller
    # handed the cloud over, as importer.load does; 10M points: 240 MB).
    cloud = replace(cloud, positions=None)
    estimated, oriented_by, ambiguous, tree = cloud.normals is None, "", 0, None
    evidence, by_rule = "", 0.0
    slivers, quantised, adaptive = 0, "", None
    known_spacing = known_cover = None
    if needs_normals:
        step("estimate")(0.0, "neighbour tree")
        tree = spacing.neighbour_tree(rel, workers)
        oriented_by = resolve_orientation(orientation, cloud.scanners is not None)
        scanners, shared = cloud.scanners, shared_row(cloud.scanners)
        scanners = (np.broadcast_to(shared - origin, scanners.shape) if shared is not None
                    else None if scanners is None else scanners - origin)
        # The file's origin in the offsets' frame (the importer's axes and scale keep it at 0):
        # where a single view's sensor sits (ORIGIN, and AUTO's range-image test).
        result, known_spacing, known_cover = normals_mod.estimate_and_orient(
            rel, normal_k, oriented_by, scanners, cloud.normals, k if bulk.all() else 0, workers, tree,
            scaled(progress, *step.span("estimate", "orient")), close_gaps=hole_free and cloud.radii is None,
            viewpoint=-origin)
        cloud = replace(cloud, normals=result.normals, oriented=True)
        ambiguous = int(result.ambiguous.sum())
        # (a share: the notes are written after the importer has let go of the arrays)
        oriented_by, evidence, by_rule = result.mode, result.evidence, result.by_rule / len(result.normals)
        slivers, quantised, adaptive = result.slivers, result.quantised, result.adaptive
    whole = bool(bulk.all())  # no copies of a 10M-point cloud (nor an index of it) when nothing is left out
    inliers = None if whole else np.flatnonzero(bulk)
    radii_tree = tree if whole else None  # the normals' k-d tree when it is the bulk's
    if radii_tree is None and cloud.radii is None:  # built here (as analyse would) for the local cap too
        radii_tree = spacing.neighbour_tree(local if whole else local[inliers], workers)
    try:
        hood = spacing.analyse(local if whole else local[inliers], cloud.normals if whole else cloud.normals[inliers],
                               k, workers, progress=step("radii"),
                               tree=radii_tree, known_spacing=known_spacing,
                               close_gaps=hole_free and cloud.radii is None, known_cover=known_cover)
    except spacing.SpacingError as e:
        raise CloudFileError(f"{path}: {e}") from None
    prepared = PreparedCloud(cloud, origin, local, cloud.radii, hood, outliers, first_outlier,
                             outliers > 0 and drop_outliers, normals_estimated=estimated, normals_oriented=oriented_by,
                             orientation_evidence=evidence, oriented_by_rule=by_rule, ambiguous=ambiguous,
                             normal_k=normal_k if estimated else 0, statistical_outliers=statistical,
                             statistical_ratio=statistical_ratio, slivers=slivers, quantised=quantised,
                             adaptive=adaptive)
    if cloud.radii is None:
        base = hood.covering if hood.covering is not None else hood.spacing
        radii = base  # the bulk is every point (no 10M-point copy); else the strays get theirs below
        if not whole:  # the strays: their distance to their k-th nearest point, among all
            strays = np.flatnonzero(~bulk)
            radii = np.empty(len(local), np.float32)
            radii[inliers] = base
            kk = min(k, len(local) - 1)
            dist, _ = spacing.neighbour_tree(local, workers).knn_at(local[strays], kk + 1)  # each finds itself first
            radii[strays] = dist[:, kk]
        cap = np.float32(RADIUS_CAP * np.percentile(hood.spacing, RADIUS_CAP_PERCENTILE))
        clamped = radii > cap
        radii = np.minimum(radii, cap)
        prepared.clamped_radii, prepared.radius_cap = int(clamped.sum()), float(cap)
        prepared.locally_capped = local_cap(radii, radii_tree, inliers)
        prepared.radii = radii
    lost = rounding > PRECISION_FRACTION * prepared.radii
    if lost.any():
        prepared.lost_precision, prepared.precision_error = int(lost.sum()), float(rounding[lost].max())
        prepared.precision_step = float(np.spacing(np.abs(local[lost]).max()))
        prepared.extent = extent
    return prepared
