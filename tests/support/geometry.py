"""Analytic shapes and truth for the tests."""
from __future__ import annotations

import numpy as np


def fibonacci_sphere(n: int, radius: float = 1.0, centre=(0.0, 0.0, 0.0)):
    """n nearly evenly spaced points on a sphere, with their exact normals."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5 ** 0.5) * i
    normals = np.column_stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)])
    return normals * radius + np.asarray(centre, dtype=np.float64), normals


def random_sphere(n: int, radius: float = 1.0, seed: int = 0):
    """n points drawn uniformly at random on a sphere about the origin (seeded), with their
    exact normals."""
    p = np.random.default_rng(seed).normal(size=(n, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    return p * radius, p


def sphere_cloud(n: int, radius: float = 1.0, seed: int = 0):
    """A closed unit-sphere splat cloud: (centres, normals, radii), randomly rotated by `seed`.
    Radii are 1.5x the mean spacing sqrt(4 pi r^2 / n), so the discs overlap without holes."""
    centres, normals = fibonacci_sphere(n, radius)
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    spacing = np.sqrt(4 * np.pi * radius**2 / n)
    return centres @ q.T, normals @ q.T, np.full(n, 1.5 * spacing)


def ray_sphere(origins, directions, centre, radius):
    """Nearest positive hit distance per ray (inf on a miss); directions are unit."""
    oc = origins - np.asarray(centre)
    b = np.einsum("ij,ij->i", oc, directions)
    c = np.einsum("ij,ij->i", oc, oc) - radius ** 2
    disc = b * b - c
    t = np.full(len(origins), np.inf)
    ok = disc >= 0
    t[ok] = -b[ok] - np.sqrt(disc[ok])
    t[t <= 0] = np.inf
    return t


def angle_deg(a, b):
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.degrees(np.arccos(np.clip(np.einsum("...i,...i->...", a, b), -1, 1)))


def blender_camera_rays(world_from_camera, width, height, *, lens=50.0, sensor_width=36.0, sensor_height=24.0,
                        sensor_fit="AUTO", shift_x=0.0, shift_y=0.0, ortho_scale=None):
    """Pixel-centre rays of a Blender camera, written from Blender's documented model
    (BKE_camera_params_compute_viewplane), independently of the add-on's code: the fitted
    sensor side spans `width` (horizontal fit) or `height` pixels, shift is in units of
    that side, and the camera looks down its local -Z. Square pixels. Returns world-space
    origins, unit directions and the unit view axis, row-major from the top row."""
    if sensor_fit == "AUTO":
        fit, sensor = ("HORIZONTAL" if width >= height else "VERTICAL"), sensor_width
    else:
        fit, sensor = sensor_fit, (sensor_width if sensor_fit == "HORIZONTAL" else sensor_height)
    fitted = width if fit == "HORIZONTAL" else height
    # Size of one pixel on the plane at unit distance (perspective) or in world units (ortho).
    pix = (ortho_scale if ortho_scale is not None else sensor / lens) / fitted
    j, i = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    x = (j - width / 2 + shift_x * fitted) * pix
    y = (height / 2 - i + shift_y * fitted) * pix
    m = np.asarray(world_from_camera, dtype=np.float64)
    rot, eye = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0), m[:3, 3]
    if ortho_scale is None:
        local_d = np.stack([x, y, -np.ones_like(x)], axis=-1).reshape(-1, 3)
        origins = np.tile(eye, (len(local_d), 1))
    else:
        local_d = np.tile([0.0, 0.0, -1.0], (x.size, 1))
        origins = eye + np.stack([x, y, np.zeros_like(x)], axis=-1).reshape(-1, 3) @ rot.T
    d = local_d @ rot.T
    return origins, d / np.linalg.norm(d, axis=1, keepdims=True), -rot[:, 2]


def sphere_truth(origins, directions, axis, centre, radius):
    """Per ray: hit mask, planar depth, world normal, and how far (in world units) the
    ray passes from the silhouette (|distance to centre - radius|)."""
    t = ray_sphere(origins, directions, centre, radius)
    hit = np.isfinite(t)
    p = origins + directions * np.where(hit, t, 0)[:, None]
    depth = (p - origins) @ axis
    oc = np.asarray(centre) - origins
    along = np.einsum("ij,ij->i", oc, directions)
    miss_distance = np.linalg.norm(oc - directions * along[:, None], axis=1)
    return hit, depth, (p - centre) / radius, np.abs(miss_distance - radius), along


def cube_cloud(per_edge: int, half: float = 1.0, on_edges: bool = False):
    """Points on the six faces of the cube [-half, half]^3 on a grid offset from the edges by
    half a step, with exact face normals: sharp edges and corners. on_edges: the grid runs
    onto the edges instead, so edge and corner points exist once per face, each with that
    face's normal (what a CAD mesh's vertex cloud looks like)."""
    h = 2 * half / per_edge
    g = np.linspace(-half, half, per_edge + 1) if on_edges else (np.arange(per_edge) + 0.5) * h - half
    u, v = (a.ravel() for a in np.meshgrid(g, g))
    pts, nrm = [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            p = np.zeros((len(u), 3))
            others = [k for k in range(3) if k != axis]
            p[:, others[0]], p[:, others[1]], p[:, axis] = u, v, sign * half
            n = np.zeros_like(p)
            n[:, axis] = sign
            pts.append(p)
            nrm.append(n)
    return np.concatenate(pts), np.concatenate(nrm)


def ray_box(origins, directions, half: float = 1.0, lo=None, hi=None):
    """Nearest positive hit distance on the cube [-half, half]^3, or the axis-aligned box
    from lo to hi (inf on a miss), and the face normal there (the slabs method)."""
    lo, hi = (-half, half) if lo is None else (np.asarray(lo, np.float64), np.asarray(hi, np.float64))
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / directions
        t0 = (lo - origins) * inv
        t1 = (hi - origins) * inv
    tn = np.minimum(t0, t1).max(axis=1)
    tf = np.maximum(t0, t1).min(axis=1)
    hit = (tn <= tf) & (tf > 0) & (tn > 0)
    t = np.where(hit, tn, np.inf)
    axis = np.argmax(np.minimum(t0, t1), axis=1)
    normal = np.zeros_like(origins)
    rows = np.arange(len(origins))
    normal[rows, axis] = -np.sign(directions[rows, axis])
    return t, normal
