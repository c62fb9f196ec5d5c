"""Normals for clouds whose files have none: PCA over the k nearest neighbours, then a
consistent orientation.

Estimation: each point's normal is the eigenvector of the smallest eigenvalue of the
covariance of its k nearest neighbours (itself included), computed in the compiled core
(PointIndex.pca: the search, the covariance in float64 about the point, the
eigenvector in closed form with Jacobi rotations where the eigenvalues nearly repeat),
in chunks of points in the k-d tree's own (spatially coherent) order.

Orientation (the PCA axis has no sign):
- SCANNER: towards the scanner that saw the point (E57 poses, a PCD's VIEWPOINT);
- ORIGIN: towards the file's origin (one viewpoint there: a depth-camera or stereo frame);
- UP: towards +Z (aerial data);
- AUTO: by the cloud's geometry, whatever its file format (see orient_auto): the scanners
  when known; else a range image seen from the file's origin is oriented towards it
  (ORIGIN); else a cloud whose bulk is a terrain (open sheets facing up or down) upward
  (UP); else each component's side by visibility (rays over the splats of a sample of the
  cloud: the side from which its points are seen escapes), where that evidence is strong;
  else as PROPAGATE;
- PROPAGATE: along the neighbour graph. Hoppe et al.'s minimum spanning tree over the
  k-NN graph with edge weights 1 - |n_i . n_j|, so that the tree runs along smooth parts
  and crosses creases as late as possible, plus a term |n . d| (d: the edge's unit
  direction, averaged over both ends) that makes edges between the two sides of a thin
  sheet expensive: their normals are parallel, so the first term alone happily joins them
  and flips one side. Each point's sign then agrees with its parent's in a breadth-first
  walk from a seed per connected component: the point farthest from the component's
  centroid, oriented away from it (outward). A flat component (its seed's normal nearly
  perpendicular to the outward direction) or an open sheet (its oriented normals' sum at
  least OPEN_SHEET x their count: a terrain, a facade) is turned so that its normals' sum
  points up (+Z; +Y, +X for vertical planes). The graph's steps are native (graph_weights,
  spanning_forest by Boruvka's algorithm, forest_traversal, chain_flips), on the cloud
  renumbered so that neighbours lie close in memory: in the import's k-d tree's order, or in
  Morton order (spatial_order) when there is no tree.
In SCANNER, ORIGIN and UP modes a point whose rule is unclear (the normal within AMBIGUOUS_RULE of
perpendicular to the scanner's direction or to +Z: grazing views, walls in aerial data)
takes its sign by propagation from its neighbours instead: from the anchor fewest tree
edges away (one as many edges from two anchors takes the sign of whichever the walk reaches
it from first; the walk's order follows the renumbering, not the file's).

Noise (depth cameras, stereo): a sensor's noise and depth quantisation (a Kinect's depth
steps are 2.85e-3 z^2: 6 cm at 4.5 m, eight times the pixel spacing there) turn a surface
into terraces and risers at the scale of a few samples, and a fit over 16 neighbours gives
the terrace's normal (45 degrees off on a wall turned 35 degrees from the camera) or the
riser's (a sliver, standing out of the wall). The terraces need neighbourhoods of 128 points
and more: where the depth is quantised (quantised_depth: one coordinate axis in few steps,
shared by neighbours, coarse against the spacing), a point whose neighbourhood spans fewer than
QUANT_SPAN steps takes a fit over a wider one (adaptive_normals). The slivers are mended:
a point whose normal is more than SLIVER_ANGLE off the consensus of its GRAPH_K nearest (the
dominant axis of their normals, sign-free), where those agree among themselves (the
consensus explains at least SLIVER_COHERENCE of their spread: not a crease, where they
split), takes the consensus (fix_slivers, SLIVER_PASSES times). They are
counted for the import's notes.

Points whose orientation is ambiguous are counted: those oriented through a tree edge with
|n_i . n_parent| < AMBIGUOUS_EDGE (the sign guess from a neighbour more than 60 degrees
off) and those no rule or neighbour decides.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..util.progress import chunks, nothing, scaled
from . import spacing as spacing_mod
from .graph import chain_flips, forest_traversal, graph_weights, spanning_forest
from .neighbours import PointIndex, permute_table, spatial_order, take_rows
from .spacing import neighbour_tree

DEFAULT_K = 16          # PCA neighbours: enough for a stable plane fit with noise, small enough for creases
GRAPH_K = 8             # neighbours in the orientation graph
MIN_POINTS = 3          # a plane needs three points
AMBIGUOUS_EDGE = 0.5    # cos 60 degrees
AMBIGUOUS_RULE = 0.2    # cos 78 degrees
ACROSS_WEIGHT = 1.0     # the weight of |n . d| against 1 - |n_i . n_j|
# A component whose oriented normals sum to at least this x their count is an open sheet
# (faces up, see orient). A closed surface's sum is about 0; a hemisphere's 0.5 (where up
# and outward agree); a terrain's or a facade's close to 1.
OPEN_SHEET = 0.5
MODES = ("AUTO", "PROPAGATE", "UP", "SCANNER", "ORIGIN")
SAMPLE_SEED = 0  # the range-image test's and visibility's samples: the same cloud, the same answer
# AUTO's terrain: the open sheets (OPEN_SHEET) whose normals' sum is within 45 degrees of
# vertical hold at least half the points. Then every point with a clear up is an anchor (as
# UP): an aerial scan's buildings, trees and cars are seen from above as its ground is.
TERRAIN_COSINE = 0.7
TERRAIN_SHARE = 0.5
# And the cloud is flat: its relief (the 1st to 99th percentile of its heights) at most this
# share of its wider horizontal side. Terrains are wide for their relief (autzen's airborne
# tile: 0.08; a mountain tile of 1 km rises a few hundred metres); a single view of an object
# from above is about as deep as it is wide (the Stanford bunny's range scans: 0.62 and 0.75,
# and two of them registered faced inwards on 2 % of the points under the upward rule).
TERRAIN_RELIEF = 0.5
# The range-image test (range_image). Its sample: percentiles of a share of 1e5 points are
# within about 0.1 % of the true ones, far below the margins of the thresholds below.
VIEW_SAMPLE = 100_000
VIEW_MIN_POINTS = 100    # fewer: no test (nothing to bin)
# The median angle between the normals and the lines of sight at most 60 degrees: a sensor
# measures surfaces it sees at steep angles (a depth camera loses returns beyond about 70
# degrees); a terrain seen from a file origin at sea level, far below or beside it, is
# seen almost edge-on.
VIEW_FACING = 0.5
# The lines of sight's cone (half-angle, degrees) holding all but VIEW_CONE_PERCENTILE % of
# the sample: wider than any depth or stereo camera's field of view (a Kinect's diagonal half-
# angle is 35, wide-angle stereo about 60) and narrower than a half space, which an object
# around its origin always exceeds. The percentile lets a few stray returns lie outside.
VIEW_CONE = 80.0
VIEW_CONE_PERCENTILE = 1.0
VIEW_CELL = 1.0          # angular cells one sample spacing (k-th neighbour) wide: a few points each
VIEW_MAX_SLOPE = 10.0    # the depth spread of a cell seen at more than 84 degrees is bounded
VIEW_DEPTH = 3.0         # sample spacings of noise (depth quantisation) within one layer
VIEW_FIRST = 0.95        # a second layer (an object's back) holds about half the points
# Visibility (visibility): its occluders are this many points of the cloud at most (a BVH
# of 2e5 discs builds in a few hundredths of a second); rays per side and probe; probes per
# component and in all; the cap of directions (a ray within 20 degrees of the tangent plane
# meets the neighbours' discs of a curved surface); how far out a ray starts (radii of its
# probe's disc). A probe's vote is clear when its sides' escape shares differ by at least
# VISIBILITY_CLEAR and the lesser is at most VISIBILITY_ENCLOSED; a component is decided by at least VISIBILITY_MIN_VOTES clear votes of
# which VISIBILITY_AGREE agree.
VISIBILITY_SAMPLE = 200_000
VISIBILITY_COVER = 2.0
VISIBILITY_RAYS = 16
VISIBILITY_PROBES = 64
VISIBILITY_MAX_PROBES = 8192
VISIBILITY_CONE = 70.0
VISIBILITY_START = 2.0
VISIBILITY_CLEAR = 0.25
VISIBILITY_ENCLOSED = 0.5
VISIBILITY_MIN_VOTES = 8
VISIBILITY_AGREE = 0.8
SLIVER_ANGLE = 30.0     # degrees: the measure of a sliver standing out of a surface
# The consensus must explain this share of its neighbours' normals' spread (mean cos^2 to it):
# at a 90-degree crease the neighbours split between two faces (0.5) and a point between them
# is not a sliver. Measured (office1, slivers 5.90 % before): 0.75 (cos^2 30 degrees) fixes
# 4.52 %, 0.6 3.82 %, 0.5 3.71 %; the clean fandisk's normal error rises by 0.11, 0.12, 0.12
# degrees. SLIVER_PASSES = 2 (a fixed sliver makes its neighbour's consensus coherent), fandisk
# +0.13 degrees: 4.45 % as fix_slivers runs (only the points off their nearest neighbour are
# tested); 3.37 % when every point is (3 passes: 3.25 %), for 0.25 s a million points more.
SLIVER_COHERENCE = 0.6
SLIVER_PASSES = 2
# Depth quantisation (quantised_depth, adaptive_normals). The detector looks at QUANT_SAMPLE
# points and their GRAPH_K nearest. A coordinate axis is quantised when at least QUANT_EQUAL
# of the sample have a neighbour at exactly their coordinate on it, the cloud takes at least
# QUANT_MIN_LEVELS distinct values on it (a staircase needs steps: one plane at z = 0 is
# none), and the median gap between a sample point's value and the next is at least
# QUANT_RATIO times its distance to its nearest neighbour (then a fit over DEFAULT_K
# neighbours, about 4.5 spacings across, spans fewer than 3 levels on a surface turned 10
# degrees from the axis, and its normal can be off by that much). Measured (equal share,
# ratio): the depth z of PCL's Kinect and stereo frames 91-100 %, 0.61-6.5; their x and y
# 32-95 %, at most 0.015; airborne LAS (1 cm steps) z 39 %, 0.02; the E57 at most 6 %,
# 0.007; bun000's scan lines (x, a lateral grid: points on the surface, not moved) 6 %,
# 0.48, and its y and z (ASCII decimals) 27-29 %, 0.004. Exactly one axis must be quantised
# (a depth sensor's; a lattice is quantised along all three).
QUANT_SAMPLE = 20_000
QUANT_EQUAL = 0.5
QUANT_MIN_LEVELS = 10
QUANT_RATIO = 0.25
# Adaptive neighbourhoods (adaptive_normals): a point keeps its DEFAULT_K fit when its
# neighbourhood spans at least QUANT_SPAN local depth steps (4 levels: two terraces and the
# risers between them, whose mean slope is the surface's); else the fit of the nearest point
# of a random subsample of 1/2, 1/4, ... 1/QUANT_MAX_FRACTION of the cloud over its own
# DEFAULT_K nearest in the subsample (the same number of points over a disc twice, four
# times ... as large: 32 to 1024 neighbours' reach at the cost of 16), the first that spans
# as many steps. Measured on tests/support/frames.kinect_frame (noise 0.3 steps, walls at
# 2-5 m): mean error 54.7 degrees at 16 neighbours; spans of 2 steps 11.1, 3 steps 6.1;
# fraction up to 1/64 (a wall turned 35 degrees at 5 m spans 3 steps over about 40 pixels).
QUANT_SPAN = 3.0
QUANT_MAX_FRACTION = 64
_CHUNK = 1 << 15


@dataclass
class Orientation:
    normals: np.ndarray      # (N,3) float32 unit, oriented
    ambiguous: np.ndarray    # (N,) bool: the points whose orientation was ambiguous
    mode: str                # the rule that decided: SCANNER, ORIGIN, UP, VISIBILITY or PROPAGATE
    components: int          # connected components of the neighbour graph
    by_rule: int = 0         # points whose sign a rule decided (the others took theirs by propagation)
    evidence: str = ""       # why AUTO chose its rule, for the import notes (empty: not AUTO)
    slivers: int = 0         # normals replaced by their neighbours' consensus (fix_slivers)
    quantised: str = ""      # the depth quantisation found (quantised_depth), in words; "": none
    adaptive: dict = None    # neighbourhood reach (points) -> how many normals were fitted over it


def _sample(n: int, size: int) -> np.ndarray:
    """Sorted distinct indices of min(n, size) seeded random draws from `n` points (with
    replacement: the duplicates drawn are dropped): the same cloud, the same sample."""
    return np.unique(np.random.default_rng(SAMPLE_SEED).integers(0, n, min(n, size)))


def estimate(points: np.ndarray, k: int = DEFAULT_K, workers: int = -1, tree=None, progress=None,
             graph=None, spacing=None, cover=None) -> np.ndarray:
    """(N,3) float64 unit normals (unoriented) by PCA over the k nearest neighbours.
    progress: progress.ProgressFn, called between chunks (it may raise Cancelled). graph:
    an (N, m) int32 array to fill with each point's m nearest (itself first), m <= k + 1,
    for orient() to reuse instead of searching again. spacing: (m, (N,) float32 array) to
    fill with each point's distance to its m-th nearest other point (m <= k), the splat
    radius's spacing (spacing.analyse) without a search of its own; cover (needs spacing):
    (m, (N,) float32 array) to fill with the uncapped gap-closing radii among the m <= k
    nearest (spacing.covering_radii's rule, with the PCA normal: its sign does not matter)."""
    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    if n < MIN_POINTS:
        raise ValueError(f"need at least {MIN_POINTS} points to estimate normals, got {n}")
    k = int(min(max(k, 2), n - 1))
    tree = tree if tree is not None else neighbour_tree(pts, workers)
    out = np.empty((n, 3))
    order = tree.order
    width = 0 if graph is None else graph.shape[1]
    spacing_k = 0 if spacing is None else spacing[0]
    cover_k = 0 if cover is None else cover[0]
    for start in chunks(n, _CHUNK, progress, "estimating normals"):
        idx = order[start:start + _CHUNK]
        out[idx], nbr, dist, gaps = tree.pca(idx, k, width, spacing_k, cover_k, spacing_mod.COVER_HOLE,
                                             spacing_mod.COVER_MAX_GAP)
        if graph is not None:
            graph[idx] = nbr
        if spacing is not None:
            spacing[1][idx] = dist
        if cover is not None:
            cover[1][idx] = gaps
    return out


def estimate_and_orient(points: np.ndarray, k: int = DEFAULT_K, mode: str = "PROPAGATE", scanners=None,
                        axes=None, radius_k: int = 0, workers: int = -1, tree=None, progress=None,
                        close_gaps: bool = False, viewpoint=None):
    """(Orientation, spacing or None, cover or None): estimate() then orient() sharing one
    neighbour search (the orientation's graph and, for radius_k in 1..k, each point's
    distance to its radius_k-th nearest other point and, close_gaps, its uncapped
    gap-closing radius: spacing.analyse's known_spacing and known_cover). axes: the file's
    own unoriented normals (only orient() runs). progress: its first 2/3 the estimation.
    viewpoint: the file's origin in these coordinates (orient's)."""
    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    tree = tree if tree is not None else neighbour_tree(pts, workers)
    estimating = axes is None
    share = 2.0 / 3.0 if estimating else 0.0
    graph = spacing = cover = None
    if estimating and k >= GRAPH_K and n > k + 1:
        graph = np.empty((n, GRAPH_K + 1), np.int32)
        if 1 <= radius_k <= k:
            spacing = (radius_k, np.empty(n, np.float32))
            if close_gaps and 2 <= spacing_mod.COVER_K <= k:
                cover = (spacing_mod.COVER_K, np.empty(n, np.float32))
    slivers = 0
    quantised, adaptive = "", None
    if estimating:
        axes = estimate(pts, k, workers, tree, progress=scaled(progress, 0.0, share), graph=graph, spacing=spacing,
                        cover=cover)
        if graph is not None:
            axis, levels, quantised = quantised_depth(pts, graph)
            if axis >= 0:
                adaptive = adaptive_normals(pts, axes, tree, axis, levels, k)
            fixed = fix_slivers(axes, graph)
            for _ in range(SLIVER_PASSES - 1):
                fixed |= fix_slivers(axes, graph)
            slivers = int(fixed.sum())
    result = orient(pts, axes, mode, scanners, workers=workers, tree=tree, progress=scaled(progress, share, 1.0),
                    graph=graph, viewpoint=viewpoint)
    result.slivers, result.quantised, result.adaptive = slivers, quantised, adaptive
    return result, None if spacing is None else spacing[1], None if cover is None else cover[1]


def quantised_depth(points: np.ndarray, graph: np.ndarray) -> tuple[int, np.ndarray, str]:
    """(axis, levels, evidence): the coordinate axis along which the depth is quantised (see
    QUANT_*; -1: none), the cloud's distinct values along it (sorted; empty when none) and
    the finding in words. graph: (N, 1 + m) the point, then its m nearest."""
    pts = np.asarray(points)
    n = len(pts)
    found = (-1, np.zeros(0), "")
    if n < QUANT_MIN_LEVELS or graph.shape[1] < 2:
        return found
    idx = _sample(n, QUANT_SAMPLE)
    nbr = graph[idx, 1:]
    gap = np.linalg.norm(pts[idx] - pts[nbr[:, 0]], axis=1)
    quantised = []
    for axis in range(3):
        depth = pts[:, axis]
        equal = float((depth[nbr] == depth[idx, None]).any(axis=1).mean())
        if equal < QUANT_EQUAL:  # no sort of the cloud's coordinates then
            continue
        levels = np.unique(depth)
        if len(levels) < QUANT_MIN_LEVELS:
            continue
        step = local_steps(levels, depth[idx])
        ratio = float(np.median(np.where(np.isfinite(step) & (gap > 0), step / np.maximum(gap, 1e-300), 0.0)))
        if ratio >= QUANT_RATIO:
            quantised.append((axis, levels, f"{'xyz'[axis]} takes {len(levels):,} distinct values, {equal:.0%} of a "
                                            f"sample's points share theirs with a neighbour, steps a median {ratio:.2g} "
                                            "point spacings"))
    # One axis: a sensor's depth. Several: a lattice (voxel centres, a grid), whose faces
    # along the axes are one level each: no staircase to span, and the search for more
    # levels would spread their fits over the edges.
    return quantised[0] if len(quantised) == 1 else found


def local_steps(levels: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """Each depth's distance to the nearest other of the sorted distinct `levels` (it is one
    of them): the quantisation step there (inf with a single level)."""
    gaps = np.diff(levels)
    i = np.searchsorted(levels, depth)
    return np.minimum(np.r_[gaps, np.inf][i], np.r_[np.inf, gaps][i])


def _spans(depth: np.ndarray, rows: np.ndarray, ids: np.ndarray, need: np.ndarray) -> np.ndarray:
    """(len(rows),) bool: the depths of each row and its neighbours `ids` span at least the
    row's `need` (depth and need: per point)."""
    d = depth[ids]
    own = depth[rows]
    return np.maximum(d.max(axis=1), own) - np.minimum(d.min(axis=1), own) >= need[rows]


def adaptive_normals(points: np.ndarray, normals: np.ndarray, tree, axis: int, levels: np.ndarray, k: int) -> dict:
    """Refits, in place, the (N,3) `normals` (PCA over the k nearest, by `tree`) of the points
    whose neighbourhood spans fewer than QUANT_SPAN depth steps along `axis` over wider
    neighbourhoods of subsamples (see QUANT_SPAN); returns {reach: count} (reach: the points
    of the full cloud a fit's neighbourhood spans, k for the points kept), over every point."""
    pts = np.asarray(points)
    n = len(pts)
    depth = np.ascontiguousarray(pts[:, axis])
    # Slightly less than the span asked, so that float rounding of equal steps cannot miss it.
    need = QUANT_SPAN * local_steps(levels, depth) * (1 - 1e-9)
    order = tree.order
    short = np.zeros(n, bool)
    for start in range(0, n, _CHUNK):
        rows = order[start:start + _CHUNK]
        short[rows] = ~_spans(depth, rows, tree.knn(rows, k)[1], need)
    counts = {k: int(n - short.sum())}
    rest = np.flatnonzero(short)
    key = np.random.default_rng(SAMPLE_SEED).random(n)
    fraction = 2
    while len(rest) and fraction <= QUANT_MAX_FRACTION:
        sub = np.flatnonzero(key < 1.0 / fraction)  # nested: each subsample holds the next
        if len(sub) <= k:
            break
        index = PointIndex(pts[sub], tree.threads)
        fits, spans = np.empty((len(sub), 3)), np.empty(len(sub), bool)
        for start in range(0, len(sub), _CHUNK):
            rows = index.order[start:start + _CHUNK]
            fits[rows], graph, _, _ = index.pca(rows, k, k + 1)
            spans[rows] = _spans(depth[sub], rows, graph[:, 1:], need[sub])
        nearest = index.knn_at(pts[rest], 1)[1][:, 0]
        take = spans[nearest] if fraction < QUANT_MAX_FRACTION else np.ones(len(rest), bool)
        normals[rest[take]] = fits[nearest[take]]
        counts[k * fraction] = int(take.sum())
        rest = rest[~take]
        fraction *= 2
    counts[k] += len(rest)  # a subsample too small to search: they keep their fit over k
    return {reach: c for reach, c in counts.items() if c}


def fix_slivers(normals: np.ndarray, graph: np.ndarray) -> np.ndarray:
    """Gives each sliver (see the module's text) its neighbours' consensus normal, in place;
    returns an (N,) bool array, True for them. normals: (N,3) float64 unit, unoriented; graph: (N, 1 + m) the point,
    then its m nearest."""
    fixed = np.zeros(len(normals), bool)
    cos_limit = np.cos(np.radians(SLIVER_ANGLE))
    for start in range(0, len(normals), _CHUNK):
        # Candidates first: a sliver is off its nearest neighbour too (one gather, not m, and
        # no power iteration for the bulk: 1M points, 0.2 s instead of 2 s).
        near = normals[graph[start:start + _CHUNK, 1]]
        own_all = normals[start:start + _CHUNK]
        rows = start + np.flatnonzero(np.abs(np.einsum("ci,ci->c", own_all, near)) < cos_limit)
        if not len(rows):
            continue
        own = normals[rows]
        nb = normals[graph[rows, 1:]]                      # (c, m, 3)
        # The dominant axis of the neighbours' normals (sign-free: sum n n^T): power
        # iteration from the point's own normal; three steps settle it when the neighbours
        # agree, the only case acted on.
        c = own
        for _ in range(3):
            c = np.einsum("cmi,cm->ci", nb, np.einsum("cmi,ci->cm", nb, c))
            c /= np.maximum(np.linalg.norm(c, axis=1, keepdims=True), 1e-300)
        coherence = (np.einsum("cmi,ci->cm", nb, c) ** 2).mean(1)
        sliver = (np.abs(np.einsum("ci,ci->c", own, c)) < cos_limit) & (coherence >= SLIVER_COHERENCE)
        if sliver.any():
            normals[rows[sliver]] = c[sliver]
            fixed[rows[sliver]] = True
    return fixed


def _fraction(report, start: float, end: float, message: str):
    """A native step's progress (a fraction of the step) as orient's report of `message`."""
    return lambda fraction: report(start + (end - start) * fraction, message)


def orient(points: np.ndarray, normals: np.ndarray, mode: str = "PROPAGATE", scanners=None,
           k: int = GRAPH_K, workers: int = -1, tree=None, progress=None, graph=None,
           viewpoint=None) -> Orientation:
    """Flips `normals` (unit, any sign) consistently; see the module's text. progress: as
    for estimate. The graph's steps (weights, spanning forest, traversal) are native
    (graph_weights, spanning_forest, forest_traversal), on `workers` threads. viewpoint:
    (3,) the file's origin in these coordinates (ORIGIN; AUTO's range-image test)."""
    if mode not in MODES:
        raise ValueError(f"unknown orientation mode {mode!r}")
    pts = np.asarray(points, dtype=np.float64)
    nrm = np.asarray(normals, dtype=np.float64)
    n = len(pts)
    k = int(min(k, n - 1))
    unusable = ~np.isfinite(nrm).all(axis=1)
    if unusable.any():
        raise ValueError(f"point {np.flatnonzero(unusable)[0]}: its normal is not finite (cannot be oriented)")
    if viewpoint is not None:
        viewpoint = np.asarray(viewpoint, dtype=np.float64).reshape(3)
    if mode == "ORIGIN":
        if viewpoint is None:
            raise ValueError("orientation towards the file's origin needs the origin's position")
        scanners = viewpoint
    evidence = ""
    report = progress or nothing
    table = None
    if mode == "AUTO" and scanners is not None:
        mode, evidence = "SCANNER", "the file's scanner positions"
    elif mode == "AUTO" and viewpoint is not None and n > k + 1:
        table = _neighbour_table(pts, k, tree, graph, workers)
        seen, evidence = range_image(pts, nrm, viewpoint, table)
        if seen:
            mode, scanners = "ORIGIN", viewpoint
    # Rules first: where they decide, they are the anchors of the propagation.
    anchor_sign = np.zeros(n, np.int8)
    if mode in ("SCANNER", "ORIGIN"):
        if scanners is None:
            raise ValueError("orientation towards the scanner needs the scanners' positions")
        d = np.asarray(scanners, dtype=np.float64) - pts
        c = np.einsum("ij,ij->i", nrm, d) / np.maximum(np.linalg.norm(d, axis=1), 1e-300)
    elif mode == "UP":
        c = nrm[:, 2]
    if mode in ("SCANNER", "ORIGIN", "UP"):
        _rule_anchors(anchor_sign, c)
        if (anchor_sign != 0).all():
            return Orientation((nrm * anchor_sign[:, None]).astype(np.float32), np.zeros(n, bool), mode, 1, n,
                               evidence)

    if n < 2:  # no neighbour to agree with: the sign is the rule's, or as it is
        signs = np.where(anchor_sign < 0, -1.0, 1.0)
        return Orientation((nrm * signs[:, None]).astype(np.float32), anchor_sign == 0,
                           "PROPAGATE" if mode == "AUTO" else mode, n, int((anchor_sign != 0).sum()), evidence)
    threads = workers if workers > 0 else 0  # scipy's -1 (all cores) is the core's 0
    report(0.0, "orienting normals: neighbour graph")
    if table is None:
        table = _neighbour_table(pts, k, tree, graph, workers)
    # The graph's steps run on the cloud renumbered in space: on a
    # file's random order every neighbour is a cache miss (10M points: 42 s instead of 6 s,
    # plus 5 s to renumber).
    # `perm` maps the new numbers to the caller's; ties below are broken in the caller's.
    # The k-d tree's order is such a renumbering already (its leaves are compact in space).
    perm = tree.order if tree is not None and len(tree) == n else spatial_order(pts, threads)
    report(0.03, "orienting normals: neighbour graph")
    # Column 0 of a row is the point itself (or, among duplicate points, one at distance 0).
    nbr = permute_table(table, perm, slice(1, k + 1), threads)
    del table
    report(0.1, "orienting normals: neighbour graph")
    p, m, anchor_sign = take_rows(pts, perm, threads), take_rows(nrm, perm, threads), anchor_sign[perm]
    sample = None
    if mode == "AUTO":  # visibility's sample, with each one's distance to its k-th neighbour
        sample = _sample(n, VISIBILITY_SAMPLE)
        sample_gap = np.linalg.norm(p[sample] - p[nbr[sample, k - 1]], axis=1)
    w = graph_weights(p, m, nbr, ACROSS_WEIGHT, threads,
                      _fraction(report, 0.15, 0.3, "orienting normals: neighbour graph"))
    report(0.3, "orienting normals: spanning tree")
    forest = spanning_forest(nbr, w, threads, _fraction(report, 0.3, 0.8, "orienting normals: spanning tree"))
    del nbr, w
    report(0.8, "orienting normals: propagation")
    walk = _Walk(p, m, forest, perm)
    del forest
    negative, ambiguous, seeds, flat = walk(anchor_sign, _fraction(report, 0.85, 0.95,
                                                                   "orienting normals: propagation"))
    labels, n_comp, counts = walk.labels, walk.n_comp, walk.counts
    # The sums serve the seeded components only (open sheets, flat ones): none, no sums.
    sums = walk.sums(negative) if len(seeds) else None
    open_sheet = walk.open_sheets(seeds, sums) if len(seeds) else np.zeros(0, bool)
    if mode != "AUTO":
        walk.edges = None  # no second walk: the forest's memory back (80 MB at 10M points)
    else:
        # Visibility first: the components it decides are no terrain (an object's fragments
        # are open sheets too); then the terrain test on the rest. Its candidates (open sheets
        # facing up or down, in a level cloud) are known before: when they cannot make a
        # terrain, the forest is let go before visibility runs.
        terrain = np.zeros(n_comp, bool)
        terrain[labels[seeds[open_sheet]]] = True
        length = np.sqrt(np.einsum("ij,ij->i", sums, sums))
        terrain &= np.abs(sums[:, 2]) >= TERRAIN_COSINE * length
        lo, hi = np.percentile(p[sample], (1.0, 99.0), axis=0)
        level = hi[2] - lo[2] <= TERRAIN_RELIEF * max(hi[0] - lo[0], hi[1] - lo[1])
        if not (level and counts[terrain].sum() / n >= TERRAIN_SHARE):
            walk.edges = None
        report(0.95, "orienting normals: visibility")
        decided, evidence = visibility(p, m, negative, labels, n_comp, sample, sample_gap, threads)
        terrain &= decided == 0
        share = counts[terrain].sum() / n if level else 0.0
        if share >= TERRAIN_SHARE:
            # A terrain's bulk: every point with a clear up takes it (as UP), on the components
            # visibility left undecided (an object standing on the ground keeps its outside).
            mode = "UP"
            terrain_evidence = (f"terrain: {share:.0%} of the points lie on open sheets whose normals face up or "
                                "down on the whole, which visibility cannot orient")
            evidence = terrain_evidence + (f"; {evidence}" if (decided != 0).any() else "")
            undecided = np.flatnonzero(decided[labels] == 0)
            anchor_sign[undecided] = _rule_anchors(anchor_sign[undecided], m[undecided, 2])
            # The decided components have no anchor: the walk seeds them as the first walk did
            # (the same seed, the same tree), and their visibility sign is applied below.
            negative, ambiguous, seeds, flat = walk(anchor_sign, None)
            sums = walk.sums(negative)
            open_sheet = walk.open_sheets(seeds, sums)
        else:
            mode = "VISIBILITY" if (decided != 0).any() else "PROPAGATE"
        negative ^= (decided < 0)[labels]
        keep = decided[labels[seeds]] == 0  # the rest as PROPAGATE (or UP)
        seeds, open_sheet = seeds[keep], open_sheet[keep]
        flat = flat[decided[labels[flat]] == 0]
        if (decided != 0).any() and len(seeds):
            sums = walk.sums(negative)
    by_rule = int((anchor_sign != 0).sum())  # the rules' anchors (walk() took its seeds out again)

    # Flat components (no outward side): their normals' sum points up (+Z, else +Y, +X). So
    # do open sheets (a terrain, a facade): their normals agree, so their sum is most of
    # their count (a closed surface's cancel out: the integral of n dA over it is 0), and
    # "outward" from their centroid is just the slope at the farthest corner (a hilly 10M-
    # point terrain came out facing down).
    if len(seeds):
        flat = np.union1d(flat, seeds[open_sheet])
    if len(flat):
        fsums = sums[labels[flat]]
        tol = 1e-9 * counts[labels[flat]]
        key = np.where(np.abs(fsums[:, 2]) > tol, fsums[:, 2],
                       np.where(np.abs(fsums[:, 1]) > tol, fsums[:, 1], fsums[:, 0]))
        turn = np.zeros(n_comp, bool)
        turn[labels[flat]] = key < 0
        negative ^= turn[labels]
    # Back to the caller's numbering: flags scattered, the normals flipped in place there.
    flags = np.empty(n, np.uint8)
    flags[perm] = negative.view(np.uint8) | (ambiguous.view(np.uint8) << 1)
    return Orientation(np.where((flags & 1)[:, None] != 0, -nrm, nrm).astype(np.float32), flags >= 2, mode,
                       int(n_comp), by_rule, evidence)


def _rule_anchors(anchor_sign: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Sets `anchor_sign` (int8, in place; returned) to +1 or -1 where the rule's cosine `c`
    (the normal against the scanner's direction or +Z) is clear: beyond AMBIGUOUS_RULE."""
    anchor_sign[c >= AMBIGUOUS_RULE] = 1
    anchor_sign[c <= -AMBIGUOUS_RULE] = -1
    return anchor_sign


def _neighbour_table(pts, k, tree, graph, workers) -> np.ndarray:
    """(n, k+1) int32: each point itself, then its k nearest (estimate()'s graph when given)."""
    if graph is not None and graph.shape[1] >= k + 1:  # estimate()'s own neighbours
        return graph
    tree = tree if tree is not None else neighbour_tree(pts, workers)
    order = tree.order  # queried in the tree's order: a leaf of points at a time
    table = np.empty((len(pts), k + 1), np.int32)
    table[order, 0] = order
    table[order, 1:] = tree.knn(order, k)[1]
    return table


class _Walk:
    """The propagation over one spanning forest, for any set of anchors (AUTO walks twice
    when it finds a terrain). Arrays in the renumbered order (orient's `perm`). It keeps the
    forest's edges only, and orient sets them to None once no walk can follow."""

    def __init__(self, p, m, forest, perm):
        self.p, self.m, self.edges, self.perm = p, m, forest.edges, perm
        self.n_comp, self.labels = forest.components, forest.labels
        n_comp, labels = self.n_comp, self.labels
        self.counts = np.bincount(labels, minlength=n_comp)
        self.centroid = np.stack([np.bincount(labels, p[:, a], n_comp) for a in range(3)], 1) / self.counts[:, None]

    def sums(self, negative) -> np.ndarray:
        """(components, 3): each component's oriented normals summed."""
        signed = np.where(negative, -1.0, 1.0)
        return np.stack([np.bincount(self.labels, self.m[:, a] * signed, self.n_comp) for a in range(3)], 1)

    def open_sheets(self, seeds, sums) -> np.ndarray:
        """(len(seeds),) bool: the seeds' components that are open sheets (OPEN_SHEET), by
        their oriented normals' `sums` (self.sums)."""
        seeded = self.labels[seeds]
        return np.sqrt(np.einsum("ij,ij->i", sums[seeded], sums[seeded])) >= OPEN_SHEET * self.counts[seeded]

    def __call__(self, anchor_sign, progress):
        """(negative, ambiguous, seeds, flat) from the rules' anchors (anchor_sign, changed:
        the seeds are added to it)."""
        p, m, labels, n_comp, perm = self.p, self.m, self.labels, self.n_comp, self.perm
        n = len(p)
        # A seed for every component the rules leave without an anchor: its point farthest from
        # the component's centroid (of equally far ones, the last in the caller's order),
        # oriented away from the centroid.
        has_anchor = np.zeros(n_comp, bool)
        has_anchor[labels[anchor_sign != 0]] = True
        outward = p - self.centroid[labels]
        dist = np.einsum("ij,ij->i", outward, outward)
        farthest = np.zeros(n_comp)
        np.maximum.at(farthest, labels, dist)
        candidates = np.flatnonzero(dist == farthest[labels])
        candidates = candidates[np.lexsort((perm[candidates], labels[candidates]))]  # per component, last index last
        seeds = candidates[np.r_[labels[candidates][1:] != labels[candidates][:-1], True]]
        seeds = seeds[~has_anchor[labels[seeds]]]
        cos_out = np.einsum("ij,ij->i", m[seeds], outward[seeds]) / np.maximum(np.sqrt(dist[seeds]), 1e-300)
        anchor_sign[seeds] = np.where(cos_out >= 0, 1, -1)
        flat = seeds[np.abs(cos_out) < AMBIGUOUS_RULE]
        del outward, dist

        # One breadth-first walk from every anchor at once (as if from a virtual root joined to
        # each), each point's sign its parent's unless their normals point apart.
        is_anchor = anchor_sign != 0
        pred, order = forest_traversal(self.edges, is_anchor, progress)
        parent = np.where(is_anchor | (pred < 0), np.arange(n), pred)
        cos_parent = np.einsum("ij,ij->i", m, m[parent])
        flip = np.where(is_anchor, anchor_sign < 0, cos_parent < 0)
        negative = chain_flips(order, parent, flip)
        ambiguous = ~is_anchor & (np.abs(cos_parent) < AMBIGUOUS_EDGE)
        anchor_sign[seeds] = 0  # a seed is no rule's
        return negative, ambiguous, seeds, flat


def _cube_cells(u: np.ndarray, cell: float) -> np.ndarray:
    """The cells (keys) of unit directions `u` binned on a cube map whose cells are `cell`
    wide on each face (a face at distance 1: cell radians at its centre, half that at its
    edges). A cube map has no poles: a depth camera looking along an axis is binned as
    evenly as any other view."""
    a = np.abs(u)
    face = np.argmax(a, axis=1)
    rows = np.arange(len(u))
    major = a[rows, face]
    x = u[rows, (face + 1) % 3] / major
    y = u[rows, (face + 2) % 3] / major
    cells = int(np.ceil(2.0 / cell))
    ix = np.clip(np.floor((x + 1) / cell), 0, cells - 1).astype(np.int64)
    iy = np.clip(np.floor((y + 1) / cell), 0, cells - 1).astype(np.int64)
    side = face * 2 + (u[rows, face] < 0)
    return (side * cells + ix) * cells + iy


def range_image(points, normals, viewpoint, table) -> tuple[bool, str]:
    """(whether the cloud is one range image seen from `viewpoint`, the evidence in words).
    A depth-camera or stereo frame in its sensor's frame: almost every point is the first
    surface along its line of sight from there (one layer per direction), seen at angles a
    sensor measures (not grazing on the whole), and the lines of sight fit in a cone of at
    most VIEW_CONE degrees around their mean (a camera's field of view; an object around its
    own origin spreads over more than a hemisphere).
    Decided on a sample of the points (VIEW_SAMPLE) with the spacing of the sample."""
    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    idx = _sample(n, VIEW_SAMPLE)
    d = pts[idx] - viewpoint
    r = np.linalg.norm(d, axis=1)
    keep = r > 0
    idx, d, r = idx[keep], d[keep], r[keep]
    if len(idx) < VIEW_MIN_POINTS:
        return False, ""
    u = d / r[:, None]
    cos = np.abs(np.einsum("ij,ij->i", np.asarray(normals)[idx], u))
    facing = float(np.median(cos))
    if facing < VIEW_FACING:
        return False, ""
    # A sensor sees its scene from outside: the lines of sight fit in a cone narrower than a
    # half space. An object centred on its own origin (the usual export of a scanned or
    # modelled object) is one layer per direction from there too, and its directions spread
    # over more than a hemisphere, even with its bottom missing: oriented towards the origin
    # it would face inwards.
    axis = u.sum(axis=0)
    axis /= max(float(np.linalg.norm(axis)), 1e-300)
    cone = float(np.degrees(np.arccos(np.clip(np.percentile(u @ axis, VIEW_CONE_PERCENTILE), -1.0, 1.0))))
    if not cone <= VIEW_CONE:
        return False, ""
    # The sample's spacing (its points are sqrt(n / sample) times farther apart than the
    # cloud's), and angular cells a few such spacings wide as seen from the viewpoint.
    gap = np.linalg.norm(pts[idx] - pts[table[idx, -1]], axis=1) * np.sqrt(n / len(idx))
    cell = VIEW_CELL * float(np.median(gap / r))
    if not (cell > 0):
        return False, ""
    # At most half a face's width (a face spans 2): a sparse sample's cells still bin the
    # directions into several per face, not one for a whole face.
    key = _cube_cells(u, min(cell, 0.5))
    order = np.argsort(key, kind="stable")
    ks = key[order]
    starts = np.r_[0, np.flatnonzero(ks[1:] != ks[:-1]) + 1]
    nearest = np.empty(len(idx))
    nearest[order] = np.repeat(np.minimum.reduceat(r[order], starts), np.diff(np.r_[starts, len(ks)]))
    # The first layer's depth varies across a cell by its width times the slope (the tangent
    # of the angle of view, bounded: a surface seen edge-on is every depth along the cell).
    tangent = np.minimum(np.sqrt(np.maximum(1 - cos * cos, 0)) / np.maximum(cos, 1e-9), VIEW_MAX_SLOPE)
    depth = r * cell * tangent + VIEW_DEPTH * gap
    share = float((r <= nearest + depth).mean())
    if share < VIEW_FIRST:
        return False, ""
    return True, (f"a range image seen from the file's origin: {share:.1%} of a sample of {len(idx):,} points are "
                  f"the first surface along their line of sight, median angle of view "
                  f"{np.degrees(np.arccos(facing)):.0f} deg, lines of sight within {cone:.0f} deg of their mean")


def visibility(p, m, negative, labels, n_comp, sample, gap, threads) -> tuple[np.ndarray, str]:
    """((components,) int8: +1 keep, -1 flip, 0 abstain; the evidence in words). The sample's
    points become splats (radii from their spacing, so that the sample covers the surface);
    probes among them (VISIBILITY_PROBES per component at most) cast VISIBILITY_RAYS rays
    into each side of their propagated normal; the side from which more escape is the
    outside. A component is decided when enough probes see a clear difference and most of
    them agree; else it abstains (an open sheet: both sides escape)."""
    from .. import _core

    decided = np.zeros(n_comp, np.int8)
    n = len(p)
    if sample is None or len(sample) < VISIBILITY_MIN_VOTES:
        return decided, ""
    # A disc of radius gap holds about GRAPH_K points; the sample's discs cover the same area
    # with n / len(sample) times fewer: sqrt of that times larger, and VISIBILITY_COVER
    # times again so that random gaps between them close.
    radii = (VISIBILITY_COVER * gap * np.sqrt(n / (GRAPH_K * len(sample)))).astype(np.float32)
    ok = radii > 0  # a point with no distance to its neighbours (duplicates) has no disc
    sample, radii = sample[ok], radii[ok]
    if len(sample) < VISIBILITY_MIN_VOTES:  # no surface to see: no evidence either way
        return decided, ""
    signed = np.where(negative[sample], -1.0, 1.0)[:, None] * m[sample]
    splats = _core.SplatCloud(np.ascontiguousarray(p[sample], np.float32), np.ascontiguousarray(signed, np.float32),
                              np.ascontiguousarray(radii), None, np.zeros(len(sample), np.uint8), threads, None)
    # Probes: up to VISIBILITY_PROBES of each component's sample points, drawn at random: the
    # sample is in the renumbered (spatial) order, and its first points of a component lie
    # together, all on one side of it (a sphere's underside, facing the ground beneath it).
    lab = labels[sample]
    order = np.lexsort((np.random.default_rng(SAMPLE_SEED).random(len(lab)), lab))
    starts = np.r_[0, np.flatnonzero(lab[order][1:] != lab[order][:-1]) + 1]
    rank = np.arange(len(order)) - np.repeat(starts, np.diff(np.r_[starts, len(order)]))
    probes = order[rank < VISIBILITY_PROBES]
    if len(probes) > VISIBILITY_MAX_PROBES:  # the largest components' first
        size = np.bincount(lab, minlength=n_comp)
        probes = probes[np.argsort(-size[lab[probes]], kind="stable")[:VISIBILITY_MAX_PROBES]]
    nrm = signed[probes]
    # Directions: a fixed spiral over the cap within VISIBILITY_CONE of the pole, turned to
    # each probe's normal (and its negation).
    j = np.arange(VISIBILITY_RAYS) + 0.5
    z = 1 - (1 - np.cos(np.radians(VISIBILITY_CONE))) * j / VISIBILITY_RAYS
    phi = j * np.pi * (3 - np.sqrt(5))
    local = np.column_stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z])
    helper = np.where(np.abs(nrm[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    t1 = np.cross(nrm, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(nrm, t1)
    dirs = (local[None, :, :1] * t1[:, None] + local[None, :, 1:2] * t2[:, None] + local[None, :, 2:] * nrm[:, None])
    escapes = []
    for side in (1.0, -1.0):
        # the other side's cap: the directions mirrored in the tangent plane
        dd = dirs - (1 - side) * local[None, :, 2:] * nrm[:, None]
        # each ray starts VISIBILITY_START radii out, past its own disc and its neighbours'
        start = p[sample[probes]][:, None, :] + dd * (VISIBILITY_START * radii[probes])[:, None, None]
        o = np.ascontiguousarray(start.reshape(-1, 3), np.float32)
        dv = np.ascontiguousarray(dd.reshape(-1, 3), np.float32)
        cnt = len(o)
        t, ids = np.empty(cnt, np.float32), np.empty(cnt, np.int32)
        splats.trace(o, dv, 0.0, np.inf, t, ids, np.empty(cnt, np.bool_), None, threads, False, None, True)
        escapes.append((ids < 0).reshape(len(probes), VISIBILITY_RAYS).mean(axis=1))
    front, back = escapes
    vote = front - back
    comp = lab[probes]
    # A clear vote: one side escapes clearly more, and the other is mostly enclosed (a valley
    # of a terrain or a room's floor escapes fully downward, and much upward too)
    enclosed = np.minimum(front, back) <= VISIBILITY_ENCLOSED
    pos = np.bincount(comp, (vote >= VISIBILITY_CLEAR) & enclosed, n_comp)
    neg = np.bincount(comp, (vote <= -VISIBILITY_CLEAR) & enclosed, n_comp)
    votes = pos + neg
    agree = np.maximum(pos, neg)
    sure = (votes >= VISIBILITY_MIN_VOTES) & (agree >= VISIBILITY_AGREE * votes)
    decided[sure] = np.where(pos[sure] > neg[sure], 1, -1)
    if not sure.any():
        return decided, (f"visibility abstained: no component's {len(probes):,} probes saw a clear outside "
                         f"(rays escaping {front.mean():.0%} / {back.mean():.0%} of the time on either side)")
    chosen = decided[comp]
    inside = chosen != 0
    out_share = np.where(chosen > 0, front, back)[inside].mean()
    in_share = np.where(chosen > 0, back, front)[inside].mean()
    counts = np.bincount(labels, minlength=n_comp)
    return decided, (f"visibility: {int(sure.sum()):,} of {n_comp:,} components ({counts[sure].sum() / n:.0%} of the "
                     f"points), rays from {int(inside.sum()):,} probes escaping {out_share:.0%} of the time on "
                     f"the side chosen against {in_share:.0%} on the other")
