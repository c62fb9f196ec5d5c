"""Normals for clouds whose files have none: PCA over the k nearest neighbours, then a
consistent orientation.

Estimation: each point's normal is the eigenvector of the smallest eigenvalue of the
covariance of its k nearest neighbours (itself included). The k-NN queries go in chunks in
the kd-tree's own (spatially coherent) order, batched eigen-decompositions, no per-point
Python.

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
  perpendicular to the outward direction) is turned so that its normals' sum points up
  (+Z; +Y, +X for vertical planes). The graph's steps are native (core.graph_weights,
  spanning_forest by Boruvka's algorithm, forest_traversal, chain_flips), on the cloud
  renumbered in Morton order (core.spatial_order) so that neighbours lie close in memory.
In SCANNER and UP modes a point whose rule is unclear (the normal within AMBIGUOUS_RULE of
perpendicular to the scanner's direction or to +Z: grazing views, walls in aerial data)
takes its sign by propagation from its neighbours instead: from the anchor fewest tree
edges away (one as many edges from two anchors takes the sign of whichever the walk reaches
it from first; the walk's order follows the renumbering, not the file's).

Points whose orientation is ambiguous are counted: those oriented through a tree edge with
|n_i . n_parent| < AMBIGUOUS_EDGE (the sign guess from a neighbour more than 60 degrees
off) and those no rule or neighbour decides.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import core
from .progress import chunks, nothing, scaled
from .spacing import neighbour_tree

DEFAULT_K = 16          # PCA neighbours: enough for a stable plane fit with noise, small enough for creases
GRAPH_K = 8             # neighbours in the orientation graph
MIN_POINTS = 3          # a plane needs three points
AMBIGUOUS_EDGE = 0.5    # cos 60 degrees
AMBIGUOUS_RULE = 0.2    # cos 78 degrees
ACROSS_WEIGHT = 1.0     # the weight of |n . d| against 1 - |n_i . n_j|
MODES = ("PROPAGATE", "UP", "SCANNER")
_CHUNK = 1 << 15
# smallest_eigenvectors: a cross product below this x p^2 means eigenvalues too close for the
# closed form's vector (its error grows as the inverse of the gap); eigh decides those.
_EIGEN_TOLERANCE = 1e-3


@dataclass
class Orientation:
    normals: np.ndarray      # (N,3) float32 unit, oriented
    ambiguous: np.ndarray    # (N,) bool: the points whose orientation was ambiguous
    mode: str
    components: int          # connected components of the neighbour graph


def estimate(points: np.ndarray, k: int = DEFAULT_K, workers: int = -1, tree=None, progress=None,
             graph=None, spacing=None) -> np.ndarray:
    """(N,3) float64 unit normals (unoriented) by PCA over the k nearest neighbours.
    progress: progress.ProgressFn, called between chunks (it may raise Cancelled). graph:
    an (N, m) int32 array to fill with each point's m nearest (itself first), m <= k + 1,
    for orient() to reuse instead of searching again. spacing: (m, (N,) float32 array) to
    fill with each point's distance to its m-th nearest other point (m <= k), the splat
    radius's spacing (spacing.analyse) without a search of its own."""
    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    if n < MIN_POINTS:
        raise ValueError(f"need at least {MIN_POINTS} points to estimate normals, got {n}")
    k = int(min(max(k, 2), n - 1))
    tree = tree if tree is not None else neighbour_tree(pts)
    out = np.empty((n, 3))
    order = tree.indices
    for start in chunks(n, _CHUNK, progress, "estimating normals"):
        idx = order[start:start + _CHUNK]
        dist, nbr = tree.query(pts[idx], k=k + 1, workers=workers)
        if graph is not None:
            graph[idx] = nbr[:, :graph.shape[1]]
        if spacing is not None:
            spacing[1][idx] = dist[:, spacing[0]]
        out[idx] = smallest_eigenvectors(_covariances(pts[nbr]))
    return out


def estimate_and_orient(points: np.ndarray, k: int = DEFAULT_K, mode: str = "PROPAGATE", scanners=None,
                        axes=None, radius_k: int = 0, workers: int = -1, tree=None, progress=None):
    """(Orientation, spacing or None): estimate() then orient() sharing one neighbour
    search (the orientation's graph and, for radius_k in 1..k, each point's distance to its
    radius_k-th nearest other point: spacing.analyse's known_spacing). axes: the file's own
    unoriented normals (only orient() runs). progress: its first 2/3 the estimation."""
    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    tree = tree if tree is not None else neighbour_tree(pts)
    estimating = axes is None
    share = 2.0 / 3.0 if estimating else 0.0
    graph = spacing = None
    if estimating and k >= GRAPH_K and n > k + 1:
        graph = np.empty((n, GRAPH_K + 1), np.int32)
        if 1 <= radius_k <= k:
            spacing = (radius_k, np.empty(n, np.float32))
    if estimating:
        axes = estimate(pts, k, workers, tree, progress=scaled(progress, 0.0, share), graph=graph, spacing=spacing)
    result = orient(pts, axes, mode, scanners, workers=workers, tree=tree, progress=scaled(progress, share, 1.0),
                    graph=graph)
    return result, None if spacing is None else spacing[1]


def _covariances(q: np.ndarray) -> np.ndarray:
    """(n,3,3) scatter matrices of the (n,k,3) neighbourhoods about their means: the six
    distinct sums by elementwise products (twice as fast as einsum's general contraction)."""
    q = q - q.mean(axis=1, keepdims=True)
    x, y, z = q[..., 0], q[..., 1], q[..., 2]
    xx, yy, zz = (x * x).sum(1), (y * y).sum(1), (z * z).sum(1)
    xy, xz, yz = (x * y).sum(1), (x * z).sum(1), (y * z).sum(1)
    return np.stack([np.stack([xx, xy, xz], -1), np.stack([xy, yy, yz], -1), np.stack([xz, yz, zz], -1)], 1)


def smallest_eigenvectors(cov: np.ndarray) -> np.ndarray:
    """(N,3) unit eigenvectors of the smallest eigenvalue of symmetric 3x3 matrices, in
    closed form (about 10x faster than numpy's batched eigh, which calls LAPACK once per
    matrix): the eigenvalue by the trigonometric solution of the characteristic cubic
    (Smith 1961), its vector as the largest cross product of two rows of cov - lambda I.
    Matrices where that is ill-conditioned (the smallest eigenvalue nearly repeated: a
    neighbourhood along a line, or isotropic) go to eigh."""
    a = cov
    q = np.trace(a, axis1=1, axis2=2) / 3.0
    p1 = a[:, 0, 1] ** 2 + a[:, 0, 2] ** 2 + a[:, 1, 2] ** 2
    p2 = (a[:, 0, 0] - q) ** 2 + (a[:, 1, 1] - q) ** 2 + (a[:, 2, 2] - q) ** 2 + 2.0 * p1
    p = np.sqrt(p2 / 6.0)
    safe_p = np.where(p > 0, p, 1.0)
    b = (a - q[:, None, None] * np.eye(3)) / safe_p[:, None, None]
    r = np.clip(np.linalg.det(b) / 2.0, -1.0, 1.0)
    phi = np.arccos(r) / 3.0
    smallest = q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)
    m = a - smallest[:, None, None] * np.eye(3)
    crosses = np.stack([np.cross(m[:, 0], m[:, 1]), np.cross(m[:, 0], m[:, 2]), np.cross(m[:, 1], m[:, 2])], 1)
    length = np.linalg.norm(crosses, axis=2)
    best = np.argmax(length, axis=1)
    rows = np.arange(len(a))
    vec = crosses[rows, best]
    size = length[rows, best]
    # well conditioned: the cross product is of the order of p^2 (the gap between eigenvalues)
    ok = size > _EIGEN_TOLERANCE * p * p
    vec = vec / np.where(ok, size, 1.0)[:, None]
    bad = np.flatnonzero(~ok)
    if len(bad):
        vec[bad] = np.linalg.eigh(a[bad])[1][:, :, 0]
    return vec


def _fraction(report, start: float, end: float, message: str):
    """A native step's progress (a fraction of the step) as orient's report of `message`."""
    return lambda fraction: report(start + (end - start) * fraction, message)


def orient(points: np.ndarray, normals: np.ndarray, mode: str = "PROPAGATE", scanners=None,
           k: int = GRAPH_K, workers: int = -1, tree=None, progress=None, graph=None) -> Orientation:
    """Flips `normals` (unit, any sign) consistently; see the module's text. progress: as
    for estimate. The graph's steps (weights, spanning forest, traversal) are native
    (core.graph_weights, spanning_forest, forest_traversal), on `workers` threads."""
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
        tree = tree if tree is not None else neighbour_tree(pts)
        order = tree.indices  # queried in the tree's leaf order: 3x faster than in file order
        table = np.empty((n, k + 1), np.int32)
        table[order] = tree.query(pts[order], k=k + 1, workers=workers)[1]
    # The graph's steps run on the cloud renumbered in space (core.spatial_order): on a
    # file's random order every neighbour is a cache miss (10M points: 42 s instead of 6 s,
    # plus 5 s to renumber).
    # `perm` maps the new numbers to the caller's; ties below are broken in the caller's.
    perm = core.spatial_order(pts, threads)
    report(0.03, "orienting normals: neighbour graph")
    # Column 0 of a row is the point itself (or, among duplicate points, one at distance 0).
    nbr = core.permute_table(table, perm, slice(1, k + 1), threads)
    report(0.1, "orienting normals: neighbour graph")
    p, m, anchor_sign = core.take_rows(pts, perm, threads), core.take_rows(nrm, perm, threads), anchor_sign[perm]
    w = core.graph_weights(p, m, nbr, ACROSS_WEIGHT, threads,
                           _fraction(report, 0.15, 0.3, "orienting normals: neighbour graph"))
    report(0.3, "orienting normals: spanning tree")
    forest = core.spanning_forest(nbr, w, threads, _fraction(report, 0.3, 0.8, "orienting normals: spanning tree"))
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
    pred, order = core.forest_traversal(forest.edges, is_anchor,
                                        _fraction(report, 0.85, 0.95, "orienting normals: propagation"))
    del forest
    parent = np.where(is_anchor | (pred < 0), np.arange(n), pred)
    cos_parent = np.einsum("ij,ij->i", m, m[parent])
    flip = np.where(is_anchor, anchor_sign < 0, cos_parent < 0)
    negative = core.chain_flips(order, parent, flip)
    ambiguous = ~is_anchor & (np.abs(cos_parent) < AMBIGUOUS_EDGE)
    del pred, order, parent, cos_parent, flip

    # Flat components (no outward side): their normals' sum points up (+Z, else +Y, +X).
    if len(flat):
        signed = np.where(negative, -1.0, 1.0)
        sums = np.stack([np.bincount(labels, m[:, a] * signed, n_comp) for a in range(3)], 1)[labels[flat]]
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
