"""Synthetic depth-camera frames: stand-ins for the Kinect and stereo frames of issue 27 (the
real ones are benchmarks only). One small ray caster -- a camera at the origin, a scene of
planes, boxes and spheres, one ray a pixel -- then the sensor's depth noise and quantisation;
the scenes the tests use are at the end."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

try:
    from geometry import ray_box, ray_sphere
except ImportError:  # imported from the root as tests.support.frames (see __init__)
    from .geometry import ray_box, ray_sphere

# A Kinect's depth comes from an integer disparity: steps of KINECT_STEP z^2 in depth (2.85e-3:
# 1.1 cm at 2 m, 7.1 cm at 5 m; PCL's office1.pcd has exactly these steps), at
# KINECT_PIXEL radians per pixel (57 degrees over 640 pixels).
KINECT_STEP = 2.85e-3
KINECT_PIXEL = np.radians(57.0) / 640


# --- the scene ---------------------------------------------------------------------------

@dataclass(frozen=True)
class Plane:
    """The points p with normal . p = offset (normal taken as given: pass a unit one)."""
    normal: tuple
    offset: float


@dataclass(frozen=True)
class Box:
    """A box from lo to hi in its own frame; turn (3x3, its frame -> the camera's) and centre
    (in the camera's frame) place a turned one, None an axis-aligned one."""
    lo: tuple
    hi: tuple
    turn: np.ndarray | None = None
    centre: tuple = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Sphere:
    centre: tuple
    radius: float


def _hits(d, shape):
    """Ray parameter of the nearest hit (inf on a miss; origin 0, direction rows d) and the
    unoriented normal there."""
    if isinstance(shape, Plane):
        with np.errstate(divide="ignore", invalid="ignore"):
            t = shape.offset / (d @ np.asarray(shape.normal))
        return np.where(t > 0, t, np.inf), np.broadcast_to(np.asarray(shape.normal, np.float64), d.shape)
    if isinstance(shape, Box):
        if shape.turn is None:
            return ray_box(np.zeros_like(d), d, lo=shape.lo, hi=shape.hi)
        origin = (-np.asarray(shape.centre)) @ shape.turn  # the camera in the box's frame
        t, face = ray_box(np.broadcast_to(origin, d.shape), d @ shape.turn, lo=shape.lo, hi=shape.hi)
        return t, face @ shape.turn.T
    if isinstance(shape, Sphere):
        length = np.linalg.norm(d, axis=1)
        t = ray_sphere(np.zeros_like(d), d / length[:, None], shape.centre, shape.radius) / length
        with np.errstate(invalid="ignore"):
            return t, (d * t[:, None] - shape.centre) / shape.radius
    raise TypeError(f"not a scene primitive: {shape!r}")


# --- the camera --------------------------------------------------------------------------

def rays(width, height, forward=-1.0, *, focal=None, fov=None, pixel=None):
    """One ray a pixel centre, row-major from the top row, from a camera at the origin looking
    along forward x Z: y up looking down -Z (Blender's camera frame), y down looking along +Z
    (PCL's, a half turn about x), x to the right. The pixel grid is a pinhole's -- `focal` in
    pixels, or `fov` the horizontal field of view in degrees -- or equiangular, `pixel`
    radians a pixel. Each ray's z is +-1, so a ray parameter is a depth along the view axis."""
    ys, xs = np.mgrid[0:height, 0:width]
    if focal is not None:
        x, y = (xs + 0.5 - width / 2) / focal, (height / 2 - ys - 0.5) / focal
    elif fov is not None:
        t = np.tan(np.radians(fov / 2))
        x, y = (2 * (xs + 0.5) / width - 1) * t, (1 - 2 * (ys + 0.5) / height) * t * height / width
    else:
        x, y = np.tan((xs - width / 2 + 0.5) * pixel), np.tan((height / 2 - ys - 0.5) * pixel)
    if forward > 0:
        y = -y
    return np.stack([x, y, np.full(x.shape, float(forward))], -1).reshape(-1, 3)


def cast(d, scene, max_range=np.inf):
    """Cast the rays d (from rays()) into the scene, a list of primitives (the nearest hit
    wins; on a tie the first listed). Returns the depth along the view axis, NaN where a ray
    hits nothing or its hit is farther than max_range from the camera, and the true normals
    facing the camera (NaN rows there)."""
    depth, nrm = np.full(len(d), np.inf), np.full(d.shape, np.nan)
    for shape in scene:
        t, n = _hits(d, shape)
        ok = t < depth
        depth[ok], nrm[ok] = t[ok], n[ok]
    depth[~np.isfinite(depth) | (depth * np.linalg.norm(d, axis=1) > max_range)] = np.nan
    nrm[np.isnan(depth)] = np.nan
    away = np.einsum("ij,ij->i", nrm, d) > 0
    nrm[away] = -nrm[away]
    return depth, nrm


def half_turn(p, nrm):
    """Points and normals from the frame looking down -Z into PCL's (looking along +Z, y down)."""
    return p * [1, -1, -1], nrm * [1, -1, -1]


# --- the sensor: depth noise and quantisation (depth z > 0 along the view axis) -------------

def noisy(z, sigma, seed=0):
    """Gaussian depth noise of sigma x z^2 (structured light's: a disparity jitter)."""
    return z + np.random.default_rng(seed).normal(0.0, 1.0, len(z)) * sigma * z ** 2


def steps(z, step):
    """Depth rounded to fixed steps."""
    return np.round(z / step) * step


def steps_z2(z, k):
    """Depth rounded to steps of k z^2 (a disparity's steps, to first order)."""
    step = k * z ** 2
    with np.errstate(invalid="ignore"):
        return np.round(z / step) * step


def disparity_steps(z, step=None, levels=None, noise=0.0, seed=0):
    """Depth from a disparity 1/z rounded to multiples of `step` (or 1/`levels`) per metre,
    as a structured-light sensor's integer disparity: depth steps of step z^2. noise:
    Gaussian disparity noise of that many steps before rounding (a real sensor's level
    jitter)."""
    if levels is not None:
        return 1.0 / (np.round(levels / z) / levels)
    w = 1.0 / z + np.random.default_rng(seed).normal(0.0, noise * step, len(z)) if noise else 1.0 / z
    return 1.0 / (np.round(w / step) * step)


# --- the scenes the tests use ------------------------------------------------------------

def slanted_wall_frame(width=160, height=120, focal=120.0):
    """A depth sensor looking along +z (y down) at a back wall, a floor and a slanted face,
    depth quantised as a Kinect's (steps of 0.0028 z^2), NaN rows where a ray hits nothing
    within the sensor's range (3.5 m: the back wall's corners are holes). Row-major, as an
    organised PCD. Returns the points and their true normals (facing the camera)."""
    d = rays(width, height, +1.0, focal=focal)
    scene = [Plane((0.0, 0.0, 1.0), 3.0),      # back wall z = 3
             Plane((0.0, 1.0, 0.0), 0.6),      # floor y = 0.6 (y points down in a camera's frame)
             Plane((0.6, 0.0, 0.8), 1.6)]      # a slanted face n . p = 1.6
    depth, nrm = cast(d, scene, max_range=3.5)
    return d * steps_z2(depth, 0.0028)[:, None], nrm


def ball_corner_frame(width=160, height=120, focal=140.0, step=0.004, noise=0.0015, seed=0):
    """A depth camera's frame in the camera's frame (sensor at the origin, looking down +Z,
    Y down, as PCL stores it): a room corner (back wall z = 3, left wall x = -1, floor
    y = 0.8) with a box and a ball on the floor, one point per pixel. Depth has sensor noise
    (sigma `noise` x z^2, as structured light) and is quantised in steps of `step`. Returns
    the points (float64, row by row) and their true normals (facing the camera)."""
    d = rays(width, height, +1.0, focal=focal)
    scene = [Plane((0.0, 0.0, 1.0), 3.0), Plane((1.0, 0.0, 0.0), -1.0), Plane((0.0, 1.0, 0.0), 0.8),
             Box((0.0, 0.4, 1.8), (0.5, 0.8, 2.3)), Sphere((-0.4, 0.5, 2.0), 0.3)]
    depth, nrm = cast(d, scene)
    return d * steps(noisy(depth, noise, seed), step)[:, None], nrm


def box_room_frame(width=160, height=120, forward=-1.0):
    """A depth camera's frame at the origin looking along forward x Z (y up for -Z, down for
    +Z as PCL's frames), 60 degrees wide: a floor, a back wall, a side wall and a box, depth
    quantised as a structured-light sensor's (steps in disparity: 1/1200 per metre^-1, 2 cm
    at 5 m). Every ray hits. Returns the points and their true normals (facing the camera)."""
    d = rays(width, height, -1.0, fov=60.0)
    scene = [Plane((0.0, 1.0, 0.0), -1.2), Plane((0.0, 0.0, 1.0), -4.0), Plane((1.0, 0.0, 0.0), 1.5),
             Box((-0.1, -1.2, -2.9), (0.7, -0.2, -2.1))]
    depth, nrm = cast(d, scene)
    p = d * disparity_steps(depth, levels=1200.0)[:, None]
    return half_turn(p, nrm) if forward > 0 else (p, nrm)


def _unit(v):
    return tuple(np.asarray(v) / np.linalg.norm(v))


# The oblique room of kinect_frame, the camera inside looking down -Z: walls turned 55 and 66
# degrees from the view axis at 2-5 m, a back wall turned 19 degrees at about 5 m, a floor and
# a ceiling sloping towards the camera (offsets: the planes' distances from the camera). A box
# in it, turned 30 degrees about the vertical: its convex edges and creases.
_TURN = np.radians(30.0)
KINECT_ROOM = [Plane(_unit((-1.0, 0.0, -0.7)), 2.4), Plane(_unit((1.0, 0.0, -0.45)), 2.6),
               Plane(_unit((0.35, 0.0, -1.0)), 5.0), Plane(_unit((0.0, -1.0, -0.25)), 1.2),
               Plane(_unit((0.0, 1.0, -0.3)), 1.6),
               Box((-0.4, -0.5, -0.35), (0.4, 0.5, 0.35), centre=(0.3, -0.5, -2.8),
                   turn=np.array([[np.cos(_TURN), 0, np.sin(_TURN)], [0, 1, 0], [-np.sin(_TURN), 0, np.cos(_TURN)]]))]


def kinect_frame(width=640, height=480, pixel=KINECT_PIXEL, step=KINECT_STEP, noise=0.0, seed=0, forward=1.0):
    """A Kinect-like frame at the origin: KINECT_ROOM, `width` x `height` pixels of `pixel`
    radians around the view axis, the depth quantised in disparity (disparity_steps: steps of
    `step` z^2, after Gaussian disparity noise of `noise` steps). forward: as box_room_frame
    (+1: PCL's frame, the view along +Z). Returns the points and their true normals (facing
    the camera)."""
    d = rays(width, height, -1.0, pixel=pixel)
    depth, nrm = cast(d, KINECT_ROOM)
    p = d * disparity_steps(depth, step, noise=noise, seed=seed)[:, None]
    return half_turn(p, nrm) if forward > 0 else (p, nrm)
