"""The truth a splat rendering is scored against: the source triangle mesh ray-cast exactly
(Embree, through embreex) with the same pixel-centre rays."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Truth:
    hit: np.ndarray            # (P,) bool coverage
    depth: np.ndarray          # (P,) planar depth along the view axis (nan on a miss)
    smooth_normal: np.ndarray  # (P,3) interpolated corner normals (meshes.corner_normals), facing the camera
    face_normal: np.ndarray    # (P,3) geometric normal, facing the camera
    size: float                # the object's bounding-box diagonal


def cast(vertices, triangles, corner_normals, origins, directions, position, forward) -> Truth:
    """corner_normals: (F,3,3), see meshes.corner_normals."""
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, np.ascontiguousarray(vertices, np.float32), np.ascontiguousarray(triangles, np.int32))
    res = scene.run(np.ascontiguousarray(origins, np.float32), np.ascontiguousarray(directions, np.float32),
                    output=1)
    hit = res["primID"] >= 0
    t = np.where(hit, res["tfar"], np.nan).astype(np.float64)
    points = origins + directions * t[:, None]
    depth = (points - position) @ forward
    corners = corner_normals[np.where(hit, res["primID"], 0)]
    u, v = res["u"][:, None], res["v"][:, None]
    smooth = (1 - u - v) * corners[:, 0] + u * corners[:, 1] + v * corners[:, 2]
    geometric = res["Ng"].astype(np.float64)
    out = []
    for n in (smooth, geometric):
        n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
        n *= np.where(np.einsum("ij,ij->i", n, directions) > 0, -1.0, 1.0)[:, None]  # face the camera
        n[~hit] = 0
        out.append(n)
    size = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
    return Truth(hit, depth, out[0], out[1], size)
