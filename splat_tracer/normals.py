"""Normals for clouds whose files have none: PCA over the k nearest neighbours, then a
consistent orientation.

Estimation: each point's normal is the eigenvector of the smallest eigenvalue of the
covariance of its k nearest neighbours (itself included), computed in the compiled core
(core.PointIndex.pca: the search, the covariance in float64 about the point, the
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
  perpendicular to the outward direction) is turned so that its normals' sum points up
  (+Z; +Y, +X for vertical planes).
In SCANNER and UP modes a point whose rule is unclear (the normal within AMBIGUOUS_RULE of
perpendicular to the scanner's direction or to +Z: grazing views, walls in aerial data)
takes its sign by propagation from its neighbours instead.

Points whose orientation is ambiguous are counted: those oriented through a tree edge with
|n_i . n_parent| < AMBIGUOUS_EDGE (the sign guess from a neighbour more than 60 degrees
off) and those no rule or neighbour decides.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

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


@dataclass
class Orientation:
    normals: np.ndarray      # (N,3) float32 unit, oriented
    ambiguous: np.ndarray    # (N,) bool: the points whose orientation was ambiguous
    mode: str
    components: int          # connected components of the neighbour graph


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
    from . import spacing as spacing_mod

    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    if n < MIN_POINTS:
        raise ValueError(f"need at least {MIN_POINTS} points to estimate normals, got {n}")
    k = int(min(max(k, 2), n - 1))
    tree = tree if tree is not None else neighbour_tree(pts, 0 if workers < 0 else workers)
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
    from . import spacing as spacing_mod

    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    tree = tree if tree is not None else neighbour_tree(pts, 0 if workers < 0 else workers)
    estimating = axes is None
    share = 2.0 / 3.0 if estimating else 0.0
    graph = spacing = cover = None
    if estimating and k >= GRAPH_K and n > k + 1:
        graph = np.empty((n, GRAPH_K + 1), np.int32)
        if 1 <= radius_k <= k:
            spacing = (radius_k, np.empty(n, np.float32))
            if close_gaps and 2 <= spacing_mod.COVER_K <= k:
                cover = (spacing_mod.COVER_K, np.empty(n, np.float32))
    if estimating:
        axes = estimate(pts, k, workers, tree, progress=scaled(progress, 0.0, share), graph=graph, spacing=spacing,
                        cover=cover)
    result = orient(pts, axes, mode, scanners, workers=workers, tree=tree, progress=scaled(progress, share, 1.0),
                    graph=graph)
    return result, None if spacing is None else spacing[1], None if cover is None else cover[1]


def _chain_signs(parent: np.ndarray, rel: np.ndarray, done: np.ndarray) -> np.ndarray:
    """Products of the relative signs along each point's path up to a point that is done
    (whose `rel` is its absolute sign), by pointer jumping: O(N log depth), vectorised."""
    acc, jump, done = rel.astype(np.int8).copy(), parent.copy(), done.copy()
    while not done.all():
        todo = np.flatnonzero(~done)
        j = jump[todo]
        acc_j, jump_j, done_j = acc[j], jump[j], done[j]
        acc[todo] *= acc_j
        jump[todo] = jump_j
        done[todo] = done_j
    return acc


def orient(points: np.ndarray, normals: np.ndarray, mode: str = "PROPAGATE", scanners=None,
           k: int = GRAPH_K, workers: int = -1, tree=None, progress=None, graph=None) -> Orientation:
    """Flips `normals` (unit, any sign) consistently; see the module's text. progress: as
    for estimate (the steps of the propagation are single library calls: reported between them)."""
    from scipy.sparse import coo_matrix, csr_matrix
    from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree

    if mode not in MODES:
        raise ValueError(f"unknown orientation mode {mode!r}")
    pts = np.asarray(points, dtype=np.float64)
    nrm = np.asarray(normals, dtype=np.float64)
    n = len(pts)
    k = int(min(k, n - 1))
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
    report(0.0, "orienting normals: neighbour graph")
    if graph is not None and graph.shape[1] >= k + 1:  # estimate()'s own neighbours
        nbr = graph[:, :k + 1]
    else:
        tree = tree if tree is not None else neighbour_tree(pts, 0 if workers < 0 else workers)
        order = tree.order  # queried in the tree's order: a leaf of points at a time
        nbr = np.empty((n, k + 1), np.int32)
        nbr[order, 0] = order
        nbr[order, 1:] = tree.knn(order, k)[1]
    j = np.ascontiguousarray(nbr[:, 1:])
    w = np.empty((n, k))
    # The edges' weights, each point against its k neighbours, in chunks of points in the
    # tree's leaf order when there is a tree (neighbours' rows then lie close in memory).
    rows = tree.order if tree is not None else np.arange(n)
    for start in chunks(n, _CHUNK, scaled(report, 0.0, 0.4), "orienting normals: neighbour graph"):
        idx = rows[start:start + _CHUNK]
        ji = j[idx]
        ni, nj = nrm[idx], nrm[ji]
        d = pts[ji] - pts[idx, None]
        d /= np.maximum(np.linalg.norm(d, axis=2, keepdims=True), 1e-300)
        w[idx] = (1.0 - np.abs(np.einsum("nj,nkj->nk", ni, nj))
                  + ACROSS_WEIGHT * 0.5 * (np.abs(np.einsum("nj,nkj->nk", ni, d)) + np.abs(np.einsum("nkj,nkj->nk", nj, d))))
    report(0.4, "orienting normals: spanning tree")
    w = w.ravel() + 1e-9  # csgraph treats a zero weight as no edge
    # Row i holds point i's k edges: the CSR arrays are the neighbour table itself (no COO
    # conversion), and the tree may overwrite them (30 % faster at 1M points, no copy).
    graph_csr = csr_matrix((w, j.ravel(), np.arange(0, n * k + 1, k)), shape=(n, n))
    del j, w
    mst = minimum_spanning_tree(graph_csr, overwrite=True)
    del graph_csr
    report(0.8, "orienting normals: propagation")
    n_comp, labels = connected_components(mst, directed=False)

    # A seed for every component the rules leave without an anchor: its point farthest from
    # the component's centroid, oriented away from the centroid.
    has_anchor = np.zeros(n_comp, bool)
    has_anchor[labels[anchor_sign != 0]] = True
    counts = np.bincount(labels, minlength=n_comp)
    centroid = np.stack([np.bincount(labels, pts[:, a], n_comp) for a in range(3)], 1) / counts[:, None]
    outward = pts - centroid[labels]
    dist = np.einsum("ij,ij->i", outward, outward)
    by = np.lexsort((dist, labels))  # per component, farthest last
    last = np.r_[labels[by][1:] != labels[by][:-1], True]
    seeds = by[last]
    seeds = seeds[~has_anchor[labels[seeds]]]
    cos_out = np.einsum("ij,ij->i", nrm[seeds], outward[seeds]) / np.maximum(np.sqrt(dist[seeds]), 1e-300)
    anchor_sign[seeds] = np.where(cos_out >= 0, 1, -1)
    flat = seeds[np.abs(cos_out) < AMBIGUOUS_RULE]

    # One breadth-first walk from a virtual root joined to every anchor.
    anchors = np.flatnonzero(anchor_sign != 0)
    tree_edges = mst.tocoo()
    rows = np.concatenate([tree_edges.row, np.full(len(anchors), n)])
    cols = np.concatenate([tree_edges.col, anchors])
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n + 1, n + 1)).tocsr()
    _, pred = breadth_first_order(graph, n, directed=False, return_predecessors=True)
    pred = pred[:n]
    is_anchor = anchor_sign != 0
    parent = np.where(is_anchor | (pred < 0), np.arange(n), pred)
    cos_parent = np.einsum("ij,ij->i", nrm, nrm[parent])
    rel = np.where(is_anchor, anchor_sign, np.where(cos_parent >= 0, 1, -1)).astype(np.int8)
    signs = _chain_signs(parent, rel, is_anchor | (pred < 0))
    out = nrm * signs[:, None]
    ambiguous = ~is_anchor & (np.abs(cos_parent) < AMBIGUOUS_EDGE)

    # Flat components (no outward side): their normals' sum points up (+Z, else +Y, +X).
    if len(flat):
        sums = np.stack([np.bincount(labels, out[:, a], n_comp) for a in range(3)], 1)[labels[flat]]
        tol = 1e-9 * counts[labels[flat]]
        key = np.where(np.abs(sums[:, 2]) > tol, sums[:, 2], np.where(np.abs(sums[:, 1]) > tol, sums[:, 1], sums[:, 0]))
        flip = np.zeros(n_comp, bool)
        flip[labels[flat]] = key < 0
        out[flip[labels]] *= -1
    return Orientation(out.astype(np.float32), ambiguous, mode, int(n_comp))
