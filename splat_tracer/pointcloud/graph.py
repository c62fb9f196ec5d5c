"""Neighbour graphs in the compiled core (native/pointcloud/graph.h): edge weights, the minimum
spanning forest and its traversal, and the sign chain along it -- normals.orient's
propagation.

`progress` here is None or a callable taking the fraction done (0..1) of the call, run on
the calling thread between chunks of work; an exception from it stops the work and
propagates (progress.Cancelled). `threads`: 0 for all cores.
"""
from __future__ import annotations

from typing import Callable, NamedTuple, Optional

import numpy as np

from .. import _core
from ..util.arrays import as_f32, as_indices


class SpanningForest(NamedTuple):
    edges: np.ndarray   # (n - components, 2) int32: the forest's edges, as vertex pairs
    labels: np.ndarray  # (n,) int32: each vertex's connected component, numbered by smallest vertex
    components: int


def graph_weights(points, normals, neighbours, across: float = 1.0, threads: int = 0,
                  progress: Optional[Callable[[float], None]] = None) -> np.ndarray:
    """(n,k) float32 weights of the edges of the neighbour table (row i: the k points joined
    to point i): 1 - |n_i . n_j| + across * (|n_i . d| + |n_j . d|) / 2, d the edge's unit
    direction (normals.py says why). points, normals: (n,3), as float64."""
    pts = np.ascontiguousarray(points, dtype=np.float64)
    nrm = np.ascontiguousarray(normals, dtype=np.float64)
    nbr = as_indices(neighbours, "neighbours", (-1, -1))
    out = np.empty(nbr.shape, np.float32)
    _core.graph_weights(pts, nrm, nbr, float(across), out, threads=threads, progress=progress)
    return out


def spanning_forest(neighbours, weights, threads: int = 0,
                    progress: Optional[Callable[[float], None]] = None) -> SpanningForest:
    """The minimum spanning forest of the neighbour table's graph (row i: the k points joined
    to point i; an entry i in row i is no edge) under `weights` ((n,k), finite, as float32),
    ties broken by the entries' order (row-major): deterministic for any number of threads."""
    nbr = as_indices(neighbours, "neighbours", (-1, -1))
    w = as_f32(weights, "weights", nbr.shape)
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
    e = as_indices(edges, "edges", (-1, 2))
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
    p = as_indices(parent, "parent", (-1,))
    o = as_indices(order, "order", (-1,))
    f = np.ascontiguousarray(flip, dtype=bool)
    if f.shape != p.shape:
        raise ValueError(f"flip must have one entry per vertex ({len(p)}), got shape {f.shape}")
    out = np.empty(len(p), bool)
    _core.chain_flips(o, p, f, out)
    return out
