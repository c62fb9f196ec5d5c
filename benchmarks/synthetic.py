"""Synthetic scenes with exact truth, one per failure class of the visibility method
(issue 8): each is a triangle mesh (the truth, ray-cast exactly) and the point cloud made
from it. Used by benchmarks/accuracy.py and by tests/render/test_method_failure_classes.py.

- `sphere+band`:    two closed shells that intersect (a belt through a body): a torus whose
                    tube is centred on the sphere's equator, so half of it is inside.
- `thin plate`:     a closed box thinner than 3 splat radii.
- `cube+fin`:       a cube with a thin fin standing on it (one closed solid, a thin part).
- `open-face cube`: the cube without its top face (a closed guess must say open).
- `notched box`:    a box with one corner cut out (concave edges and corners).
- `non-uniform sphere`: a sphere sampled 10x more densely at one pole than the other.

Every shape is made of flat faces with their own vertices (sharp edges: a vertex never
averages two faces' normals) or of smooth closed meshes, so the truth's smooth normal is
right everywhere.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from benchmarks import meshes, scoring
from benchmarks import truth as truth_mod


@dataclass
class SyntheticScene:
    name: str
    vertices: np.ndarray   # the truth mesh
    triangles: np.ndarray
    points: np.ndarray     # the cloud made from it
    normals: np.ndarray
    view: dict             # camera_view() arguments besides the cloud and image size
    has_edges: bool        # sharp edges, whose fringes the far phase removes


def box_solid(x_edges, y_edges, z_edges, filled: np.ndarray):
    """The closed surface of a union of axis-aligned cells of a rectilinear grid: each face
    between a filled and an empty cell (or the outside) as two triangles with its own four
    vertices, oriented outward. filled: bool (nx, ny, nz)."""
    edges = [np.asarray(e, dtype=np.float64) for e in (x_edges, y_edges, z_edges)]
    padded = np.pad(filled, 1)
    verts, tris = [], []
    for axis in range(3):
        u_axis, v_axis = [k for k in range(3) if k != axis]
        # A face lies between cell i-1 and cell i along `axis` (in padded indices).
        lo = np.moveaxis(padded, axis, 0)[:-1]
        hi = np.moveaxis(padded, axis, 0)[1:]
        for sign, mask in ((1.0, lo & ~hi), (-1.0, hi & ~lo)):
            for idx in zip(*np.nonzero(mask)):
                i = idx[0]  # face at edges[axis][i] (the padded offset cancels here)
                # The cell's indices along the other two axes (np.moveaxis keeps their order).
                cu, cv = idx[1] - 1, idx[2] - 1
                u0, u1 = edges[u_axis][cu], edges[u_axis][cu + 1]
                v0, v1 = edges[v_axis][cv], edges[v_axis][cv + 1]
                quad = np.zeros((4, 3))
                quad[:, axis] = edges[axis][i]
                quad[:, u_axis] = [u0, u1, u1, u0]
                quad[:, v_axis] = [v0, v0, v1, v1]
                base = len(verts) * 4
                t = np.array([[0, 1, 2], [0, 2, 3]])
                n = np.cross(quad[1] - quad[0], quad[2] - quad[0])
                if n[axis] * sign < 0:
                    t = t[:, ::-1]
                verts.append(quad)
                tris.append(t + base)
    return np.concatenate(verts), np.concatenate(tris)


def _weighted_samples(vertices, triangles, n, weight, seed=0):
    """n area samples thinned by weight(points) in (0, 1]: the density follows the weight."""
    rng = np.random.default_rng(seed + 1)
    points, normals = meshes.area_samples(vertices, triangles, int(n / 0.3), seed=seed)
    keep = rng.uniform(size=len(points)) < weight(points)
    return points[keep][:n], normals[keep][:n]


def scenes(n_samples: int = 50000) -> list[SyntheticScene]:
    side = dict(direction=(-0.35, -1.0, -0.45), up=(0.0, 0.0, 1.0))  # from the side, a little above
    out = []

    sv, st = meshes.icosphere(5)
    tv, tt = meshes.torus(n_major=256, n_minor=48, major=1.0, minor=0.15)
    v = np.concatenate([sv, tv])
    t = np.concatenate([st, tt + len(sv)])
    p, n = meshes.area_samples(v, t, n_samples)
    out.append(SyntheticScene("sphere+band", v, t, p, n, side, False))  # smooth silhouettes only

    v, t = box_solid([-1, 1], [-1, 1], [-0.04, 0.04], np.ones((1, 1, 1), bool))
    p, n = meshes.area_samples(v, t, n_samples)
    out.append(SyntheticScene("thin plate", v, t, p, n, dict(direction=(-0.4, -1.0, -0.6), up=(0.0, 0.0, 1.0)),
                              True))

    filled = np.zeros((3, 1, 2), bool)
    filled[:, :, 0] = True
    filled[1, :, 1] = True
    v, t = box_solid([-1, -0.035, 0.035, 1], [-1, 1], [-1, 1, 2], filled)
    p, n = meshes.area_samples(v, t, n_samples)
    out.append(SyntheticScene("cube+fin", v, t, p, n, side, True))

    v, t = meshes.box(8)
    top = np.all(np.isclose(v[t][:, :, 2], 1.0), axis=1)
    t = t[~top]
    p, n = meshes.area_samples(v, t, n_samples)
    out.append(SyntheticScene("open-face cube", v, t, p, n, dict(direction=(-0.45, -1.0, -0.8), up=(0.0, 0.0, 1.0)),
                              True))

    filled = np.ones((2, 2, 2), bool)
    filled[1, 0, 1] = False  # the corner facing the camera
    v, t = box_solid([-1, 0, 1], [-1, 0, 1], [-1, 0, 1], filled)
    p, n = meshes.area_samples(v, t, n_samples)
    out.append(SyntheticScene("notched box", v, t, p, n, side, True))

    sv, st = meshes.icosphere(6)
    # Density from 1 at z = -1 to 10 at z = +1 (the weight's range, 0.1 to 1).
    p, n = _weighted_samples(sv, st, n_samples // 2, lambda q: 10 ** ((q[:, 2] - 1) / 2))
    out.append(SyntheticScene("non-uniform sphere", sv, st, p, n, side, False))
    return out


def score_methods(sc: SyntheticScene, methods: dict, width: int, height: int, radius_factor: float = 1.0) -> dict:
    """{label: scoring.score(...)} for each Method in `methods`, rendering the scene's
    cloud (k-NN radii, the importer's closed guess) from its view with pixel-centre rays."""
    from splat_tracer.pointcloud import spacing
    from splat_tracer.pointcloud.neighbours import local_frame
    from splat_tracer.render.camera import Camera
    from splat_tracer.render.method import Method
    from splat_tracer.render.splats import SplatCloud

    origin, local = local_frame(sc.points)
    hood = spacing.analyse(local, sc.normals)
    view = meshes.camera_view(sc.points, width, height, **sc.view)
    cam = Camera.look_at(**view)
    o, d = cam.rays(width, height)
    d64 = d.astype(np.float64)
    d64 /= np.linalg.norm(d64, axis=1, keepdims=True)
    truth = truth_mod.cast(sc.vertices, sc.triangles, meshes.corner_normals(sc.vertices, sc.triangles),
                           o.astype(np.float64), d64, cam.position, cam.forward)
    cam_local = Camera.look_at(**{**view, "eye": view["eye"] - origin, "target": view["target"] - origin})
    radii = spacing.covering_radii(local, sc.normals, hood.spacing)  # what the importer gives
    scene = SplatCloud(local, sc.normals, radii * radius_factor, closed=hood.closed_guess)
    out = {}
    for label, method in methods.items():
        img = scene.render(cam_local, width, height, method=method)
        out[label] = scoring.score(truth, img.rgba[..., 3].ravel() > 0.5, img.depth.ravel().astype(np.float64),
                                   img.normal.reshape(-1, 3), d64, float(np.median(hood.spacing)))
        out[label]["closed"] = hood.closed_guess
    return out
