"""Reference meshes and the point clouds made from them (benchmarks only).

The OBJ files in ../shared/data/meshes are plain `v` / `f` lists. They are read here with
numpy rather than with a mesh library because the libraries tried (trimesh) drop
unreferenced vertices, and the Stanford bunny's 35,947 vertices -- the paper's point
cloud -- include 1,113 that no face uses.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

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

    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    face_n = np.cross(b - a, c - a)  # length = 2 x area: area weighting for free
    normals = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(normals, triangles[:, k], face_n)
    length = np.linalg.norm(normals, axis=1)
    used = length > 0
    normals[used] /= length[used, None]
    if not used.all():
        _, nearest = cKDTree(vertices[used]).query(vertices[~used])
        normals[~used] = normals[used][nearest]
    return vertices, normals


def fit_camera(core, centres: np.ndarray, width: int, height: int, direction=(-0.3, -0.2, -1.0),
               up=(0.0, 1.0, 0.0), fov_y: float = 30.0):
    """A perspective camera that frames the cloud's bounding box (the meshes are y-up;
    the default looks at the model's front, +z, from slightly above and to the side)."""
    lo, hi = centres.min(axis=0), centres.max(axis=0)
    target = (lo + hi) / 2
    radius = np.linalg.norm(hi - lo) / 2
    d = np.asarray(direction, dtype=np.float64)
    d /= np.linalg.norm(d)
    distance = radius / np.tan(np.radians(fov_y) / 2) * 1.05
    return core.Camera.look_at(target - d * distance, target, up=up, fov_y=fov_y, aspect=width / height,
                               near=distance * 1e-3, far=distance * 10)
