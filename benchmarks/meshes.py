"""Reference meshes and the point clouds made from them (benchmarks only).

The OBJ files in ../shared/data/meshes are plain `v` / `f` lists. They are read here with
numpy rather than with a mesh library because the libraries tried (trimesh) drop
unreferenced vertices, and the Stanford bunny's 35,947 vertices -- the paper's point
cloud -- include 1,113 that no face uses.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from splat_tracer.render.camera import Camera

SHARED_MESHES = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "meshes"


def read_obj(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (V,3) float64, triangles (F,3) int64); polygons are fanned."""
    verts, tris = [], []
    with open(path) as f:
        for line in f:
            if line.startswith("v "):
                verts.append(line.split()[1:4])
            elif line.startswith("f "):
                idx = [int(tok.split("/")[0]) for tok in line.split()[1:]]
                idx = [i - 1 if i > 0 else len(verts) + i for i in idx]
                tris.extend([idx[0], idx[k], idx[k + 1]] for k in range(1, len(idx) - 1))
    return np.asarray(verts, dtype=np.float64), np.asarray(tris, dtype=np.int64).reshape(-1, 3)


def vertex_cloud(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every vertex with its area-weighted normal. A vertex no face uses takes the normal of
    its nearest used vertex (so the bunny keeps all 35,947 points)."""
    from scipy.spatial import cKDTree

    normals = vertex_normals(vertices, triangles)
    used = np.linalg.norm(normals, axis=1) > 0
    if not used.all():
        _, nearest = cKDTree(vertices[used]).query(vertices[~used])
        normals[~used] = normals[used][nearest]
    return vertices, normals


def camera_view(centres: np.ndarray, width: int, height: int, direction=(-0.3, -0.2, -1.0),
                up=(0.0, 1.0, 0.0), fov_y: float = 30.0) -> dict:
    """Arguments of Camera.look_at for a perspective view that frames the cloud's
    bounding box (the meshes are y-up; the default looks at the model's front, +z, from
    slightly above and to the side)."""
    lo, hi = centres.min(axis=0), centres.max(axis=0)
    target = (lo + hi) / 2
    radius = np.linalg.norm(hi - lo) / 2
    d = np.asarray(direction, dtype=np.float64)
    d /= np.linalg.norm(d)
    distance = radius / np.tan(np.radians(fov_y) / 2) * 1.05
    return dict(eye=target - d * distance, target=target, up=up, fov_y=fov_y, aspect=width / height,
                near=distance * 1e-3, far=distance * 10)


def fit_camera(centres: np.ndarray, width: int, height: int):
    """A Camera framing the cloud (see camera_view)."""
    return Camera.look_at(**camera_view(centres, width, height))


def vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals (zero for unused vertices)."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    face_n = np.cross(b - a, c - a)  # length = 2 x area: area weighting for free
    normals = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(normals, triangles[:, k], face_n)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)


# The truth's shading normals: what Blender shows with Auto Smooth at its default angle.
# Faces meeting at a vertex at a sharper angle are not averaged (a CAD model's creases stay
# sharp); gentler ones are (an organic model stays smooth).
CREASE_DEG = 60.0


def corner_normals(vertices: np.ndarray, triangles: np.ndarray, crease_deg: float = CREASE_DEG) -> np.ndarray:
    """(F,3,3) unit normals at each triangle corner: the area-weighted mean of the normals
    of the faces around the corner's vertex within crease_deg of this face's normal."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    face_n = np.cross(b - a, c - a)  # length = 2 x area
    unit = face_n / np.maximum(np.linalg.norm(face_n, axis=1, keepdims=True), 1e-300)
    corner_v = triangles.ravel()                     # corner i belongs to face i // 3
    order = np.argsort(corner_v, kind="stable")
    counts = np.bincount(corner_v, minlength=len(vertices))
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    deg = counts[corner_v]                          # faces around each corner's vertex
    first = np.repeat(np.arange(corner_v.size), deg)
    offset = np.arange(first.size) - np.repeat(np.cumsum(deg) - deg, deg)
    other = order[starts[corner_v[first]] + offset]  # every corner sharing the vertex
    fa, fb = first // 3, other // 3
    keep = np.einsum("ij,ij->i", unit[fa], unit[fb]) >= np.cos(np.radians(crease_deg))
    out = np.zeros((corner_v.size, 3))
    np.add.at(out, first[keep], face_n[fb[keep]])
    out /= np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-300)
    return out.reshape(-1, 3, 3)


def area_samples(vertices: np.ndarray, triangles: np.ndarray, n: int, seed: int = 0):
    """n points uniform by area, each with the exact (geometric) normal of its triangle."""
    rng = np.random.default_rng(seed)
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    cross = np.cross(b - a, c - a)
    area = np.linalg.norm(cross, axis=1)
    tri = rng.choice(len(triangles), size=n, p=area / area.sum())
    u, v = rng.uniform(size=(2, n))
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    points = a[tri] + (b[tri] - a[tri]) * u[:, None] + (c[tri] - a[tri]) * v[:, None]
    return points, cross[tri] / area[tri, None]


def icosphere(subdivisions: int = 6):
    """The unit sphere as a subdivided icosahedron: nearly even vertices (a UV sphere's
    crowded poles would make a poor point cloud), 10 x 4^s + 2 of them."""
    t = (1 + 5 ** 0.5) / 2
    verts = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t],
                      [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], dtype=np.float64)
    tris = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
                     [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
                     [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    for _ in range(subdivisions):
        edges = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
        unique, inverse = np.unique(edges, axis=0, return_inverse=True)
        mid = len(verts) + inverse.reshape(3, -1).T  # midpoints of edges 01, 12, 20
        verts = np.vstack([verts, (verts[unique[:, 0]] + verts[unique[:, 1]]) / 2])
        a, b, c = tris.T
        ab, bc, ca = mid.T
        tris = np.concatenate([np.column_stack(x) for x in ((a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca))])
    return verts / np.linalg.norm(verts, axis=1, keepdims=True), tris


def torus(n_major: int = 192, n_minor: int = 64, major: float = 1.0, minor: float = 0.35):
    u = np.linspace(0, 2 * np.pi, n_major, endpoint=False)
    v = np.linspace(0, 2 * np.pi, n_minor, endpoint=False)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    verts = np.column_stack([((major + minor * np.cos(vv)) * np.cos(uu)).ravel(),
                             ((major + minor * np.cos(vv)) * np.sin(uu)).ravel(), (minor * np.sin(vv)).ravel()])
    idx = np.arange(n_major * n_minor).reshape(n_major, n_minor)
    a, b = idx, np.roll(idx, -1, axis=0)
    c, d = np.roll(b, -1, axis=1), np.roll(a, -1, axis=1)
    tris = np.concatenate([np.column_stack([a.ravel(), b.ravel(), c.ravel()]),
                           np.column_stack([a.ravel(), c.ravel(), d.ravel()])])
    return verts, tris


def box(n: int = 40):
    """The cube [-1, 1]^3, each face an n x n grid of quads (sharp edges: no shared normals)."""
    g = np.linspace(-1, 1, n + 1)
    verts, tris = [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            u, v = np.meshgrid(g, g, indexing="ij")
            p = np.zeros((u.size, 3))
            others = [k for k in range(3) if k != axis]
            p[:, others[0]], p[:, others[1]], p[:, axis] = u.ravel(), v.ravel(), sign
            idx = len(np.concatenate(verts)) if verts else 0
            grid = idx + np.arange(u.size).reshape(n + 1, n + 1)
            a, b, c, d = grid[:-1, :-1], grid[1:, :-1], grid[1:, 1:], grid[:-1, 1:]
            t = np.concatenate([np.column_stack([a.ravel(), b.ravel(), c.ravel()]),
                                np.column_stack([a.ravel(), c.ravel(), d.ravel()])])
            # Orient outward: the normal of the first triangle must point along sign * axis.
            p0, p1, p2 = p[t[0] - idx]
            if np.cross(p1 - p0, p2 - p0)[axis] * sign < 0:
                t = t[:, ::-1]
            verts.append(p)
            tris.append(t)
    return np.concatenate(verts), np.concatenate(tris)
