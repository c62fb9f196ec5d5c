"""Normals for clouds whose files have none: PCA over the k nearest neighbours, then a
consistent orientation.

Estimation: each point's normal is the eigenvector of the smallest eigenvalue of the
covariance of its k nearest neighbours (itself included), computed in the compiled core
(PointIndex.pca: the search, the covariance in float64 about the point, the
eigenvector in closed form with Jacobi rotations where the eigenvalues nearly repeat),
in chunks of points in the k-d tree's own (spatially coherent) order.

Orientation (the PCA axis has no sign):
- SCANNER: towards the scanner that saw the point (E57 poses);
- UP: towards +Z (aerial data: LAS);
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
In SCANNER and UP modes a point whose rule is unclear (the normal within AMBIGUOUS_RULE of
perpendicular to the scanner's direction or to +Z: grazing views, walls in aerial data)
takes its sign by propagation from its neighbours instead: from the anchor fewest tree
edges away (one as many edges from two anchors takes the sign of whichever the walk reaches
it from first; the walk's order follows the renumbering, not the file's).

Noise (depth cameras, stereo): a sensor's noise and depth quantisation (a Kinect's depth
steps are 2.85e-3 z^2: 6 cm at 4.5 m, eight times the pixel spacing there) turn a surface
into terraces and risers at the scale of a few samples, and a fit over 16 neighbours gives
the terrace's normal (45 degrees off on a wall turned 35 degrees from the camera) or the
riser's (a sliver, standing out of the wall). The terraces need neighbourhoods of 128 points
and more (not done: measured in the commit that added fix_slivers); the slivers are mended:
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
SLIVER_ANGLE = 30.0     # degrees: the measure of a sliver standing out of a surface
# The consensus must explain this share of its neighbours' normals' spread (mean cos^2 to it):
# at a 90-degree crease the neighbours split between two faces (0.5) and a point between them
# is not a sliver. Measured (office1, slivers 5.90 % before): 0.75 (cos^2 30 degrees) fixes
# 4.52 %, 0.6 3.82 %, 0.5 3.71 %; the clean fandisk's normal error rises by 0.11, 0.12, 0.12
# degrees. SLIVER_PASSES = 2 (a fixed sliver makes its neighbour's consensus coherent): 3.37 %
# (3 passes: 3.25 %), fandisk +0.13 degrees.
SLIVER_COHERENCE = 0.6
SLIVER_PASSES = 2
MODES = ("PROPAGATE", "UP", "SCANNER")
_CHUNK = 1 << 15


@dataclass
class Orientation:
    normals: np.ndarray      # (N,3) float32 unit, oriented
    ambiguous: np.ndarray    # (N,) bool: the points whose orientation was ambiguous
    mode: str
    components: int          # connected components of the neighbour graph
    slivers: int = 0         # normals replaced by their neighbours' consensus (fix_slivers)


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
                        close_gaps: bool = False):
    """(Orientation, spacing or None, cover or None): estimate() then orient() sharing one
    neighbour search (the orientation's graph and, for radius_k in 1..k, each point's
    distance to its radius_k-th nearest other point and, close_gaps, its uncapped
    gap-closing radius: spacing.analyse's known_spacing and known_cover). axes: the file's
    own unoriented normals (only orient() runs). progress: its first 2/3 the estimation."""
    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    tree = tree if tree is not None else neighbour_tree(pts, workers)
    estimating = axes is None
    share = 2.0 / 3.0 if estimating else 0.0
    graph = spacing = cover = None
    slivers = 0
    if estimating and k >= GRAPH_K and n > k + 1:
        graph = np.empty((n, GRAPH_K + 1), np.int32)
        if 1 <= radius_k <= k:
            spacing = (radius_k, np.empty(n, np.float32))
            if close_gaps and 2 <= spacing_mod.COVER_K <= k:
                cover = (spacing_mod.COVER_K, np.empty(n, np.float32))
    if estimating:
        axes = estimate(pts, k, workers, tree, progress=scaled(progress, 0.0, share), graph=graph, spacing=spacing,
                        cover=cover)
        if graph is not None:
            fixed = fix_slivers(axes, graph)
            for _ in range(SLIVER_PASSES - 1):
                fixed |= fix_slivers(axes, graph)
            slivers = int(fixed.sum())
    result = orient(pts, axes, mode, scanners, workers=workers, tree=tree, progress=scaled(progress, share, 1.0),
                    graph=graph)
    if estimating:
        result.slivers = slivers
    return result, None if spacing is None else spacing[1], None if cover is None else cover[1]


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
           k: int = GRAPH_K, workers: int = -1, tree=None, progress=None, graph=None) -> Orientation:
    """Flips `normals` (unit, any sign) consistently; see the module's text. progress: as
    for estimate. The graph's steps (weights, spanning forest, traversal) are native
    (graph_weights, spanning_forest, forest_traversal), on `workers` threads."""
    if mode not in MODES:
        raise ValueError(f"unknown orientation mode {mode!r}")
    pts = np.asarray(points, dtype=np.float64)
    nrm = np.asarray(normals, dtype=np.float64)
    n = len(pts)
    k = int(min(k, n - 1))
    unusable = ~np.isfinite(nrm).all(axis=1)
    if unusable.any():
        raise ValueError(f"point {np.flatnonzero(unusable)[0]}: its normal is not finite (cannot be oriented)")
    # Rules first: where they decide, they are the anchors of the propagation.
    anchor_sign = np.zeros(n, np.int8)
    if mode == "SCANNER":
        if scanners is None:
            raise ValueError("orientation towards the scanner needs the scanners' positions")
        d = np.asarray(scanners, dtype=np.float64) - pts
        c = np.einsum("ij,ij->i", nrm, d) / np.maximum(np.linalg.norm(d, axis=1), 1e-300)
    elif mode == "UP":
        c = nrm[:, 2]
    if mode != "PROPAGATE":
        anchor_sign[c >= AMBIGUOUS_RULE] = 1
        anchor_sign[c <= -AMBIGUOUS_RULE] = -1
        if (anchor_sign != 0).all():
            return Orientation((nrm * anchor_sign[:, None]).astype(np.float32), np.zeros(n, bool), mode, 1)

    if n < 2:  # no neighbour to agree with: the sign is the rule's, or as it is
        signs = np.where(anchor_sign < 0, -1.0, 1.0)
        return Orientation((nrm * signs[:, None]).astype(np.float32), anchor_sign == 0, mode, n)
    report = progress or nothing
    threads = workers if workers > 0 else 0  # scipy's -1 (all cores) is the core's 0
    report(0.0, "orienting normals: neighbour graph")
    if graph is not None and graph.shape[1] >= k + 1:  # estimate()'s own neighbours
        table = graph
    else:
        tree = tree if tree is not None else neighbour_tree(pts, workers)
        order = tree.order  # queried in the tree's order: a leaf of points at a time
        table = np.empty((n, k + 1), np.int32)
        table[order, 0] = order
        table[order, 1:] = tree.knn(order, k)[1]
    # The graph's steps run on the cloud renumbered in space: on a
    # file's random order every neighbour is a cache miss (10M points: 42 s instead of 6 s,
    # plus 5 s to renumber).
    # `perm` maps the new numbers to the caller's; ties below are broken in the caller's.
    # The k-d tree's order is such a renumbering already (its leaves are compact in space).
    perm = tree.order if tree is not None and len(tree) == n else spatial_order(pts, threads)
    report(0.03, "orienting normals: neighbour graph")
    # Column 0 of a row is the point itself (or, among duplicate points, one at distance 0).
    nbr = permute_table(table, perm, slice(1, k + 1), threads)
    report(0.1, "orienting normals: neighbour graph")
    p, m, anchor_sign = take_rows(pts, perm, threads), take_rows(nrm, perm, threads), anchor_sign[perm]
    w = graph_weights(p, m, nbr, ACROSS_WEIGHT, threads,
                      _fraction(report, 0.15, 0.3, "orienting normals: neighbour graph"))
    report(0.3, "orienting normals: spanning tree")
    forest = spanning_forest(nbr, w, threads, _fraction(report, 0.3, 0.8, "orienting normals: spanning tree"))
    del nbr, w
    report(0.8, "orienting normals: propagation")
    n_comp, labels = forest.components, forest.labels

    # A seed for every component the rules leave without an anchor: its point farthest from
    # the component's centroid (of equally far ones, the last in the caller's order),
    # oriented away from the centroid.
    has_anchor = np.zeros(n_comp, bool)
    has_anchor[labels[anchor_sign != 0]] = True
    counts = np.bincount(labels, minlength=n_comp)
    centroid = np.stack([np.bincount(labels, p[:, a], n_comp) for a in range(3)], 1) / counts[:, None]
    outward = p - centroid[labels]
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
    pred, order = forest_traversal(forest.edges, is_anchor,
                                   _fraction(report, 0.85, 0.95, "orienting normals: propagation"))
    del forest
    parent = np.where(is_anchor | (pred < 0), np.arange(n), pred)
    cos_parent = np.einsum("ij,ij->i", m, m[parent])
    flip = np.where(is_anchor, anchor_sign < 0, cos_parent < 0)
    negative = chain_flips(order, parent, flip)
    ambiguous = ~is_anchor & (np.abs(cos_parent) < AMBIGUOUS_EDGE)
    del pred, order, parent, cos_parent, flip

    # Flat components (no outward side): their normals' sum points up (+Z, else +Y, +X). So
    # do open sheets (a terrain, a facade): their normals agree, so their sum is most of
    # their count (a closed surface's cancel out: the integral of n dA over it is 0), and
    # "outward" from their centroid is just the slope at the farthest corner (a hilly 10M-
    # point terrain came out facing down).
    if len(seeds):
        signed = np.where(negative, -1.0, 1.0)
        sums = np.stack([np.bincount(labels, m[:, a] * signed, n_comp) for a in range(3)], 1)
        seeded = labels[seeds]
        open_sheet = np.sqrt(np.einsum("ij,ij->i", sums[seeded], sums[seeded])) >= OPEN_SHEET * counts[seeded]
        flat = np.union1d(flat, seeds[open_sheet])
    if len(flat):
        sums = sums[labels[flat]]
        tol = 1e-9 * counts[labels[flat]]
        key = np.where(np.abs(sums[:, 2]) > tol, sums[:, 2], np.where(np.abs(sums[:, 1]) > tol, sums[:, 1], sums[:, 0]))
        turn = np.zeros(n_comp, bool)
        turn[labels[flat]] = key < 0
        negative ^= turn[labels]
    # Back to the caller's numbering: flags scattered, the normals flipped in place there.
    flags = np.empty(n, np.uint8)
    flags[perm] = negative.view(np.uint8) | (ambiguous.view(np.uint8) << 1)
    return Orientation(np.where((flags & 1)[:, None] != 0, -nrm, nrm).astype(np.float32), flags >= 2, mode,
                       int(n_comp))
