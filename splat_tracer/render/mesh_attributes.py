"""Values Cycles derives from a mesh when it is exported, for the Geometry node's Pointiness
and Random Per Island outputs: computed here the same way (from Cycles' definitions, in
numpy), carried to the core as the attributes the node programs read (render/nodes.py:
POINTINESS, RANDOM_PER_ISLAND).

Blender-free: the arrays come from blender/export/scene.py.
"""
from __future__ import annotations

import numpy as np

_U32 = 0xFFFFFFFF


def _rot(x, k):
    return ((x << np.uint32(k)) | (x >> np.uint32(32 - k))) & np.uint32(_U32)


def lookup3(*words) -> np.ndarray:
    """Bob Jenkins' lookup3 hash of 1-3 uint32 words (arrays alike), seeded as Blender and
    Cycles seed it (0xdeadbeef + 4 x the word count + 13): Cycles' hash_uint .. hash_uint3."""
    with np.errstate(over="ignore"):
        words = [np.asarray(w, np.uint64).astype(np.uint32) for w in words]
        start = np.uint32((0xDEADBEEF + (len(words) << 2) + 13) & _U32)
        a, b, c = (np.full(np.broadcast(*words).shape, start, np.uint32) for _ in range(3))
        a = a + words[0]
        if len(words) > 1:
            b = b + words[1]
        if len(words) > 2:
            c = c + words[2]
        # lookup3's final(a, b, c)
        c = (c ^ b) - _rot(b, 14)
        a = (a ^ c) - _rot(c, 11)
        b = (b ^ a) - _rot(a, 25)
        c = (c ^ b) - _rot(b, 16)
        a = (a ^ c) - _rot(c, 4)
        b = (b ^ a) - _rot(a, 14)
        c = (c ^ b) - _rot(b, 24)
    return c


def hash_uint_to_float(k) -> np.ndarray:
    """Cycles' hash_uint_to_float of uint32 words: lookup3 of one word over 0xFFFFFFFF, in
    float32 as Cycles computes it."""
    return lookup3(k).astype(np.float32) * np.float32(1.0 / _U32)


def island_roots(n_vertices: int, edges) -> np.ndarray:
    """Each vertex's island representative as Cycles finds it: a disjoint set over the
    vertices (union by rank, the larger rank's root kept, x's on a tie) joined along the
    mesh's edges in their stored order. The representative itself is what gets hashed, so
    the join order and tie rule are Cycles' own."""
    parent = list(range(n_vertices))
    rank = [0] * n_vertices

    def find(x):
        root = x
        while parent[root] != root:
            root = parent[root]
        while parent[x] != root:  # path compression (changes no root)
            parent[x], x = root, parent[x]
        return root

    for x, y in np.asarray(edges, np.int64).reshape(-1, 2).tolist():
        rx, ry = find(x), find(y)
        if rx == ry:
            continue
        if rank[rx] < rank[ry]:
            rx, ry = ry, rx
        parent[ry] = rx
        if rank[rx] == rank[ry]:
            rank[rx] += 1
    return np.array([find(v) for v in range(n_vertices)], np.int64)


def random_per_island(n_vertices: int, edges, first_vertices) -> np.ndarray:
    """(T,) float32: Cycles' Random Per Island of each triangle, the hash of the island root
    of its first corner's vertex (`first_vertices`: that vertex per loop triangle)."""
    if n_vertices == 0:
        return np.zeros(len(first_vertices), np.float32)
    roots = island_roots(n_vertices, edges)
    return hash_uint_to_float(roots[np.asarray(first_vertices, np.int64)])


def pointiness(positions, vertex_normals, edges) -> np.ndarray:
    """(V,) float32: Cycles' Pointiness of each vertex. Vertices at the same position are
    welded (their normals summed); per vertex, the angle between its normal and the mean
    of the unit vectors along its edges, over pi (0.5 on a flat patch, less where convex),
    then averaged with its edge neighbours' (a two-ring blur).
    Cycles welds vertices closer than sqrt(FLT_EPSILON) (3.5e-4, in the mesh's units); this
    welds only those at exactly the same position (what split edges and seams leave)."""
    p = np.asarray(positions, np.float64).reshape(-1, 3)
    n = len(p)
    if n == 0:
        return np.zeros(0, np.float32)
    _, first, inverse = np.unique(p, axis=0, return_index=True, return_inverse=True)
    orig = first[inverse.ravel()]  # each vertex's welded representative
    normal = np.zeros((n, 3))
    np.add.at(normal, orig, np.asarray(vertex_normals, np.float64).reshape(-1, 3))
    e = orig[np.asarray(edges, np.int64).reshape(-1, 2)]
    e = e[e[:, 0] != e[:, 1]]  # an edge between welded vertices has no direction
    e = np.unique(np.sort(e, axis=1), axis=0)  # each welded edge once
    d = p[e[:, 1]] - p[e[:, 0]]
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
    accum, count = np.zeros((n, 3)), np.zeros(n)
    np.add.at(accum, e[:, 0], d)
    np.add.at(accum, e[:, 1], -d)
    np.add.at(count, e[:, 0], 1)
    np.add.at(count, e[:, 1], 1)
    length = np.linalg.norm(normal, axis=1)
    unit = normal / np.where(length > 0, length, 1.0)[:, None]
    mean = accum / np.maximum(count, 1)[:, None]
    raw = np.where(count > 0, np.arccos(np.clip(np.einsum("ij,ij->i", unit, mean), -1.0, 1.0)) / np.pi, 0.0)
    blurred = raw.copy()
    np.add.at(blurred, e[:, 0], raw[e[:, 1]])
    np.add.at(blurred, e[:, 1], raw[e[:, 0]])
    blurred /= count + 1
    return blurred[orig].astype(np.float32)


def uv_tangents(corners, uvs) -> np.ndarray:
    """(T, 3) float32: each triangle's unit tangent (the direction of increasing u) from its
    corners' positions (T, 3, 3) and UVs (T, 3, 2); 0 where the UVs are degenerate."""
    p = np.asarray(corners, np.float64)
    t = np.nan_to_num(np.asarray(uvs, np.float64))
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    d1, d2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    tangent = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) * np.sign(det)[:, None]
    length = np.linalg.norm(tangent, axis=1, keepdims=True)
    return np.where(length > 0, tangent / np.where(length > 0, length, 1.0), 0.0).astype(np.float32)
