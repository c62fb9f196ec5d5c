"""Neighbourhood analysis on import: splat radii and the "closed surface" guess.

Radii (docs/ALGORITHM.md, "Radius"): the spacing s_i of point i is the distance to its k-th
nearest neighbour (k = 6 by default: on an evenly sampled surface a point has about six
neighbours at distance D, so s_i ~ D and radius factor 1 gives the paper's "size update",
full overlap).

Closed guess: a point is on a boundary (a hole's rim, a scan's border) when its
BOUNDARY_K nearest neighbours, seen in its tangent plane, leave an angular gap wider than
BOUNDARY_GAP: inside a surface they surround it. A closed surface has no boundary points, an open one about as
many as the square root of its point count (its rim); the cloud is guessed closed when
fewer than CLOSED_MAX_BOUNDARY x sqrt(N) points are on a boundary, which tolerates a few
noisy points but not a rim. Sharp edges do not count: a neighbour below the tangent plane
(on the other face of an edge) is unfolded across the edge, moved by its depth below the
plane along its own normal's tangential direction, which points away from the face; on a
real rim the neighbours' normals tilt towards the neighbours themselves, so nothing is
moved across the gap.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from ..util.progress import chunks
from .neighbours import PointIndex

DEFAULT_K = 6
# A splat's size comes from its distance to other points: a cloud needs at least one
# point besides each one (the importer refuses fewer distinct positions).
MIN_POINTS = 2
# The boundary test looks at this many neighbours, for a gap wider than BOUNDARY_GAP. With
# randomly sampled surfaces (50k points on a sphere) k = 12 and 150 degrees flagged 3 % of
# interior points; k = 24 and 160 degrees flags almost none, while an open patch's rim,
# whose points see a half-disc of neighbours (>= 180 degrees), is still found.
BOUNDARY_K = 24
BOUNDARY_GAP = np.radians(160.0)
CLOSED_MAX_BOUNDARY = 0.2           # x sqrt(N): an open square patch has 4 x sqrt(N)
# The boundary test costs a search of 24 neighbours and an angular sort per point, more
# than the radii's own search: beyond BOUNDARY_SAMPLE points it runs on that many points
# drawn at random (a fixed seed: the same guess every time; see BOUNDARY_RUN) and the count
# is scaled up. The guess compares the
# boundary fraction with 0.2/sqrt(N); an open surface's rim is 4/sqrt(N), so at 10M points
# 200k samples expect about 250 rim hits against a limit of about 13: far apart.
BOUNDARY_SAMPLE = 200_000
BOUNDARY_SEED = 0
# The sample is drawn as runs of this many points of the k-d tree's order (spatially
# compact patches, 6,250 of them spread over the cloud): the core answers a run a leaf at a
# time, 3-4x faster than as many lone points at 10M, whose searches each start from the
# root and miss the cache. A rim crossing a patch gives it several hits at once, which
# widens the count's spread, but 250 expected hits against a limit of 13 leave room.
BOUNDARY_RUN = 32
# Queries go in chunks of this many points, in the k-d tree's own (spatially coherent)
# order: the core then answers a leaf of points at a time (PointIndex), the chunks
# bound the memory of the (chunk, k) arrays, and progress and cancelling act between them
# (about every 0.1 s). Each chunk costs a call's threads and their last unbalanced tasks:
# at 2^16 points the 153 chunks of a 10M-point cloud's radii took 0.2 s longer.
_CHUNK = 1 << 18


class SpacingError(ValueError):
    pass


@dataclass
class Neighbourhood:
    spacing: np.ndarray      # (N,) float32 distance to the k-th nearest other point
    degenerate: int          # points whose spacing was 0 (k+ duplicates): given the median
    boundary: int            # points on a boundary (only when normals were given)
    closed_guess: bool       # boundary < CLOSED_MAX_BOUNDARY x sqrt(N)
    tested: int = 0          # points given the boundary test (all, or BOUNDARY_SAMPLE of a larger cloud)
    covering: Optional[np.ndarray] = None  # (N,) float32 gap-closing radii (close_gaps), as covering_radii's

    def describe(self) -> str:
        about = "" if self.tested >= len(self.spacing) else f"about (from {self.tested:,} sampled) "
        return (f"{about}{self.boundary} of {len(self.spacing)} points look like a boundary "
                f"(limit {CLOSED_MAX_BOUNDARY * np.sqrt(len(self.spacing)):.0f} for a closed surface)")


def neighbour_tree(points: np.ndarray, workers: int = -1):
    """The compiled core's k-d tree of the points (neighbours.PointIndex, float32), built for
    the importer's all-points queries: asked about runs of its own order (`order`), it
    answers a leaf of points at a time. Measured at 1M points on a terrain against scipy's
    cKDTree (sliding-midpoint build): build and a k = 6 search of every
    point in about a third of the time, and the gap-closing radii and PCA normals, computed
    natively beside the search, 3-4x faster than numpy over the neighbour arrays. workers:
    threads, -1 (the importer's convention, scipy's) or 0 for all cores."""
    return PointIndex(points, max(workers, 0))


def _boundary_count(tree, idx: np.ndarray, normals: np.ndarray, k: int) -> int:
    """How many of the points `idx` of the tree are on a boundary: their k nearest leave an
    angular gap wider than BOUNDARY_GAP (see the module's text; the compiled core computes
    the angles, PointIndex.widest_gaps)."""
    return int((tree.widest_gaps(idx, normals, k) > BOUNDARY_GAP).sum())


def _sample_runs(n: int, count: int) -> np.ndarray:
    """`count` (a multiple of BOUNDARY_RUN, at most n) positions in [0, n), rising, in runs
    of BOUNDARY_RUN, the runs drawn at random (seeded) among the aligned blocks."""
    runs = count // BOUNDARY_RUN
    blocks = np.random.default_rng(BOUNDARY_SEED).choice(n // BOUNDARY_RUN, runs, replace=False)
    return (np.sort(blocks)[:, None] * BOUNDARY_RUN + np.arange(BOUNDARY_RUN)).ravel()


def analyse(points: np.ndarray, normals=None, k: int = DEFAULT_K, workers: int = -1, progress=None,
            tree=None, known_spacing=None, close_gaps: bool = False, known_cover=None) -> Neighbourhood:
    """k-NN spacing of every point and, with normals, the boundary count and closed guess
    and (close_gaps) the gap-closing radii (`covering_radii`), from the same search.
    progress: progress.ProgressFn, called between chunks (it may raise Cancelled); tree: a
    neighbour_tree of `points` already built; known_spacing, known_cover: the (N,) distances
    to the k-th nearest other point and the uncapped gap-closing radii when a search already
    found them (normals.estimate)."""
    pts = np.asarray(points)  # the tree holds float32: no float64 copy of a 10M-point cloud
    n = len(pts)
    if n < MIN_POINTS:
        raise SpacingError(f"need at least {MIN_POINTS} points to estimate the spacing (or a 'radius' property)")
    k = int(min(k, n - 1))
    kq = int(min(max(k, BOUNDARY_K if normals is not None else 0), n - 1))
    nrm = None if normals is None else np.asarray(normals)
    cover_k = int(min(COVER_K, n - 1)) if close_gaps and nrm is not None else 0
    if cover_k < 2:
        cover_k = 0
    if nrm is not None:
        nrm = np.asarray(nrm, np.float32)  # the core's queries take directions of any length, in float32
    tree = tree if tree is not None else neighbour_tree(pts, workers)
    order = tree.order  # the tree's order: neighbouring points are adjacent
    searched = known_spacing is None or (cover_k and known_cover is None)
    spacing = np.empty(n, np.float32) if known_spacing is None else np.array(known_spacing, np.float32)
    cover = None if not cover_k else (np.empty(n, np.float32) if known_cover is None
                                      else np.array(known_cover, np.float32))
    # The points given the boundary test (normals given): every point of a small cloud, else
    # a sample of runs of the tree's order (positions in `order`, rising), tested chunk by
    # chunk beside the radii: one pass, one progress (0.23 s for 200k points at 10M, as long
    # as in a pass of their own after the search).
    at = None if nrm is None or n <= BOUNDARY_SAMPLE else _sample_runs(n, BOUNDARY_SAMPLE)
    tested = n if at is None else len(at)  # (every point, without normals: nothing to test, nothing sampled)
    hits = 0

    def boundary_hits(b: int, e: int) -> int:  # of the tested points at positions [b, e) of the order
        if at is None:
            return _boundary_count(tree, order[b:e], nrm, kq)
        i, j = np.searchsorted(at, (b, e))
        return _boundary_count(tree, order[at[i:j]], nrm, kq) if j > i else 0

    if searched:
        for start in chunks(n, _CHUNK, progress, "splat radii"):
            idx = order[start:start + _CHUNK]
            # the spacing and the gap-closing radii (normals given) from one search (no (n, k)
            # arrays), written by the core at each point's own row (no scatter here)
            tree.radii(idx, k, nrm if cover_k else None, cover_k, COVER_HOLE, COVER_MAX_GAP, out=(spacing, cover),
                       cover_cap=COVER_CAP)  # at least the spacing, at most COVER_CAP x it (below)
            if nrm is not None:
                hits += boundary_hits(start, start + len(idx))
    elif nrm is not None:  # the radii were known: the boundary test alone
        for start in chunks(n, _CHUNK, progress, "splat radii: closed surface guess"):
            hits += boundary_hits(start, min(n, start + _CHUNK))
    boundary = int(round(hits * n / tested)) if nrm is not None else 0
    degenerate = spacing <= 0
    n_degenerate = int(degenerate.sum())
    if n_degenerate:
        good = spacing[~degenerate]
        if good.size == 0:
            raise SpacingError("all points coincide: the spacing is zero everywhere")
        spacing[degenerate] = np.median(good)
    if cover is not None and not searched:  # known_cover: at least the spacing, at most COVER_CAP x it
        np.maximum(cover, spacing, out=cover)  # in place: no 10M-point temporaries
        np.minimum(cover, COVER_CAP * spacing, out=cover)
    elif cover is not None and n_degenerate:  # the core applied the rule; a point sharing its position
        cover[degenerate] = spacing[degenerate]  # with k+ others gets the median, like its spacing
    closed = nrm is not None and boundary < CLOSED_MAX_BOUNDARY * np.sqrt(n)
    return Neighbourhood(spacing, n_degenerate, boundary, bool(closed), tested, cover)


# Statistical outlier removal (as PCL's StatisticalOutlierRemoval and Open3D's
# remove_statistical_outlier do it): a point whose mean distance to its SOR_K nearest
# neighbours exceeds the mean of that distance over the cloud by more than `ratio`
# standard deviations is an outlier. 20 neighbours is Open3D's documented example and
# enough for the mean distance of a surface point to be stable.
SOR_K = 20


def statistical_inliers(points: np.ndarray, ratio: float, k: int = SOR_K, workers: int = -1, progress=None,
                        tree=None) -> np.ndarray:
    """(N,) bool: the points kept by statistical outlier removal (see SOR_K)."""
    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    k = int(min(k, n - 1))
    if k < 1:
        return np.ones(n, bool)
    tree = tree if tree is not None else neighbour_tree(pts, workers)
    order = tree.order
    mean = np.empty(n)
    for start in chunks(n, _CHUNK, progress, "statistical outliers"):
        idx = order[start:start + _CHUNK]
        mean[idx] = tree.knn(idx, k)[0].mean(axis=1)
    return mean <= mean.mean() + ratio * mean.std()


def knn_spacing(points: np.ndarray, k: int = DEFAULT_K, workers: int = -1) -> tuple[np.ndarray, int]:
    """(spacing, number of degenerate points): see `analyse`."""
    hood = analyse(points, None, k, workers)
    return hood.spacing, hood.degenerate


# Gap-closing radii (docs/ALGORITHM.md, "Radius"; the import option Close Gaps). A point of
# the surface is left uncovered when it is farther from every sample than their radii: the
# worst such points are the Voronoi vertices, the centres of the empty circles through three
# samples. Each sample's radius is raised towards the largest empty circle it is on (in its
# tangent plane, among its COVER_K nearest neighbours), so that gaps between samples close. Circles
# across a gap wider than COVER_MAX_GAP are a boundary's (a rim, a hole, a silhouette seen
# in the tangent plane) and are not covered: that would fatten the boundary. Nor are circles
# wider than COVER_HOLE x the k-NN spacing (holes). The raise is capped at COVER_CAP x the
# spacing: on the benchmark's randomly sampled clouds 1.3 leaves few pinholes at 640x480,
# and a larger cap fattens silhouettes. A circle counts when it is empty: no neighbour
# strictly inside (a long thin triangle's circle is not a gap). The compiled core computes
# the rule (native/pointcloud/neighbours.cpp, covering_radius), beside the neighbour search.
COVER_K = 12
COVER_MAX_GAP = np.radians(162.0)  # 0.9 pi: a near-straight boundary still counts as one
COVER_CAP = 1.3
COVER_HOLE = 3.0  # circles up to this x the spacing count as gaps between samples


def covering_radii(points: np.ndarray, normals: np.ndarray, spacing: np.ndarray, workers: int = -1,
                   tree=None, progress=None) -> np.ndarray:
    """(N,) float32 radii that close the gaps between samples: each point's k-NN spacing
    raised to the largest empty circle it is on, at most COVER_CAP x the spacing (see above).
    tree: a neighbour_tree of `points` already built; progress: as analyse's. The rule is
    computed in the compiled core (PointIndex.covering)."""
    nrm = np.asarray(normals, dtype=np.float32)  # directions of any length (the core normalises them)
    s = np.asarray(spacing, dtype=np.float32)
    k = int(min(COVER_K, len(points) - 1))
    if k < 2:
        return s.copy()
    tree = tree if tree is not None else neighbour_tree(points, workers)
    out = np.empty(len(s), np.float32)
    for start in chunks(len(s), _CHUNK, progress, "splat radii: closing gaps"):
        idx = tree.order[start:start + _CHUNK]  # the tree's (spatially coherent) order
        out[idx] = tree.covering(idx, nrm, s, k, COVER_HOLE, COVER_MAX_GAP)
    return np.minimum(out, COVER_CAP * s)
