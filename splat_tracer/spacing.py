"""Splat radii from the local point spacing (ALGORITHM.md, "Radius").

The spacing s_i of point i is the distance to its k-th nearest neighbour (k = 6 by
default: on an evenly sampled surface a point has about six neighbours at distance D, so
s_i ~ D and radius factor 1 gives the paper's "size update", full overlap).
"""
from __future__ import annotations

import numpy as np

DEFAULT_K = 6
# Queries go in chunks of this many points, in the kd-tree's own (spatially coherent)
# order, so that each chunk walks the same few branches: this is what keeps 10M-point
# scans within seconds and bounds the memory of the (chunk, k+1) distance arrays.
_CHUNK = 1 << 16


class SpacingError(ValueError):
    pass


def knn_spacing(points: np.ndarray, k: int = DEFAULT_K, workers: int = -1) -> tuple[np.ndarray, int]:
    """Distance from each point to its k-th nearest other point.

    Returns (spacing float32 (N,), number of points whose spacing was 0 because at least k
    other points share their position; those get the median spacing instead).
    """
    from scipy.spatial import cKDTree  # imported here: only import needs scipy

    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    if n < 2:
        raise SpacingError("need at least 2 points to estimate the spacing (or a 'radius' property)")
    k = int(min(k, n - 1))
    tree = cKDTree(pts)
    order = tree.indices  # leaf order of the tree: neighbouring points are adjacent
    spacing = np.empty(n, np.float32)
    for start in range(0, n, _CHUNK):
        idx = order[start:start + _CHUNK]
        dist, _ = tree.query(pts[idx], k=k + 1, workers=workers)  # +1: the point itself
        spacing[idx] = dist[:, k]
    degenerate = spacing <= 0
    n_degenerate = int(degenerate.sum())
    if n_degenerate:
        good = spacing[~degenerate]
        if good.size == 0:
            raise SpacingError("all points coincide: the spacing is zero everywhere")
        spacing[degenerate] = np.median(good)
    return spacing, n_degenerate
