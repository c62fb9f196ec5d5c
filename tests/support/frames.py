"""Depth-camera frames with quantised depth, and their true normals: stand-ins for the
Kinect and stereo frames of issue 27 (the real ones are benchmarks only)."""
from __future__ import annotations

import numpy as np

# A Kinect's depth comes from an integer disparity: steps of KINECT_STEP z^2 in depth (2.85e-3:
# 1.1 cm at 2 m, 7.1 cm at 5 m; PCL's office1.pcd has exactly these steps), at
# KINECT_PIXEL radians per pixel (57 degrees over 640 pixels).
KINECT_STEP = 2.85e-3
KINECT_PIXEL = np.radians(57.0) / 640


def _facing(p, nrm):
    """The normals turned towards the camera at the origin."""
    return np.where((np.einsum("ij,ij->i", nrm, -p) < 0)[:, None], -nrm, nrm)


def depth_frame(width=160, height=120, forward=-1.0):
    """A depth camera's frame at the origin looking along forward x Z (y up for -Z, down for
    +Z as PCL's frames): a floor, a back wall, a side wall and a box, depth quantised as a
    structured-light sensor's (steps in disparity: 1/1200 per metre^-1, 2 cm at 5 m).
    Returns the points and their true normals (facing the camera)."""
    ys, xs = np.mgrid[0:height, 0:width]
    t = np.tan(np.radians(30))
    d = np.stack([(2 * (xs + 0.5) / width - 1) * t, (1 - 2 * (ys + 0.5) / height) * t * height / width,
                  -np.ones(xs.shape)], -1).reshape(-1, 3)
    best, nrm = np.full(len(d), np.inf), np.zeros_like(d)
    for n_, c in ((np.array([0, 1.0, 0]), -1.2), (np.array([0, 0, 1.0]), -4.0), (np.array([1.0, 0, 0]), 1.5)):
        dn = d @ n_
        with np.errstate(divide="ignore", invalid="ignore"):
            hit = c / dn
        ok = (hit > 0) & (hit < best)
        best[ok], nrm[ok] = hit[ok], n_
    lo, hi = np.array([-0.1, -1.2, -2.9]), np.array([0.7, -0.2, -2.1])
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = lo / d, hi / d
    near, far = np.minimum(t1, t2).max(1), np.maximum(t1, t2).min(1)
    box = (near <= far) & (near > 0) & (near < best)
    axis = np.argmax(np.minimum(t1, t2), 1)
    rows = np.arange(len(d))
    face = np.zeros_like(d)
    face[rows, axis] = -np.sign(d[rows, axis])
    best[box], nrm[box] = near[box], face[box]
    seen = np.isfinite(best)
    p, nrm = d[seen] * best[seen, None], nrm[seen]
    z = -p[:, 2]
    p *= (1.0 / (np.round(1200.0 / z) / 1200.0) / z)[:, None]  # the quantised depth
    nrm = _facing(p, nrm)
    if forward > 0:  # PCL's camera frame: the view along +Z, y down (a half turn about x)
        p, nrm = p * [1, -1, -1], nrm * [1, -1, -1]
    return p, nrm


# The oblique room of kinect_frame: outward normals (unnormalised) and distances from the
# camera of the planes bounding it (the camera inside, looking down -Z): walls turned 55 and
# 66 degrees from the view axis at 2-5 m, a back wall turned 19 degrees at about 5 m, a
# floor and a ceiling sloping towards the camera.
ROOM = ((((-1.0, 0.0, -0.7)), 2.4), (((1.0, 0.0, -0.45)), 2.6), (((0.35, 0.0, -1.0)), 5.0),
        (((0.0, -1.0, -0.25)), 1.2), (((0.0, 1.0, -0.3)), 1.6))
# A box in the room, turned 30 degrees about the vertical: its convex edges and creases.
BOX_CENTRE, BOX_HALF, BOX_TURN = np.array([0.3, -0.5, -2.8]), np.array([0.4, 0.5, 0.35]), np.radians(30.0)


def kinect_frame(width=640, height=480, pixel=KINECT_PIXEL, step=KINECT_STEP, noise=0.0, seed=0, forward=1.0):
    """A Kinect-like frame at the origin: the oblique room (ROOM) and a turned box (BOX_*),
    `width` x `height` pixels of `pixel` radians around the view axis, the depth z quantised
    in disparity: 1/z rounded to a multiple of `step` (z steps of step z^2), after Gaussian
    disparity noise of `noise` steps (a real sensor's level jitter). forward: as depth_frame
    (+1: PCL's frame, the view along +Z). Returns the points and their true normals (facing
    the camera)."""
    ys, xs = np.mgrid[0:height, 0:width]
    d = np.stack([np.tan((xs - width / 2 + 0.5) * pixel), np.tan((height / 2 - ys - 0.5) * pixel),
                  -np.ones(xs.shape)], -1).reshape(-1, 3)
    best, nrm = np.full(len(d), np.inf), np.zeros_like(d)
    for n_, c in ROOM:  # inside a convex room: each ray leaves it through the nearest plane ahead
        n_ = np.asarray(n_) / np.linalg.norm(n_)
        dn = d @ n_
        with np.errstate(divide="ignore", invalid="ignore"):
            hit = np.where(dn > 0, c / dn, np.inf)
        ok = hit < best
        best[ok], nrm[ok] = hit[ok], n_
    cos, sin = np.cos(BOX_TURN), np.sin(BOX_TURN)
    turn = np.array([[cos, 0, sin], [0, 1, 0], [-sin, 0, cos]])  # box frame -> camera frame
    o_box, d_box = (-BOX_CENTRE) @ turn, d @ turn
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (-BOX_HALF - o_box) / d_box, (BOX_HALF - o_box) / d_box
    near, far = np.minimum(t1, t2).max(1), np.maximum(t1, t2).min(1)
    box = (near <= far) & (near > 0) & (near < best)
    axis = np.argmax(np.minimum(t1, t2), 1)
    rows = np.arange(len(d))
    face = np.zeros_like(d)
    face[rows, axis] = -np.sign(d_box[rows, axis])
    best[box], nrm[box] = near[box], (face @ turn.T)[box]
    p = d * best[:, None]
    z = -p[:, 2]
    w = 1.0 / z + np.random.default_rng(seed).normal(0.0, noise * step, len(z)) if noise else 1.0 / z
    zq = 1.0 / (np.round(w / step) * step)  # the quantised depth, along each pixel's ray
    p[:, :2] *= (zq / z)[:, None]
    p[:, 2] = -zq  # exactly: equal disparities, equal depths (as a sensor's lookup table gives)
    nrm = _facing(p, nrm)
    if forward > 0:
        p, nrm = p * [1, -1, -1], nrm * [1, -1, -1]
    return p, nrm
