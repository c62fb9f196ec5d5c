"""The splat-cloud renderer over the compiled core, usable from plain Python (no Blender needed).

    from splat_tracer.render.camera import Camera
    from splat_tracer.render.method import Method
    from splat_tracer.render.splats import SplatCloud
    cloud = SplatCloud(centres, normals, radii, closed=True)   # (N,3), (N,3), (N,) arrays
    surf = cloud.trace_surface(origins, directions)           # the paper's visibility method
    hits = cloud.trace(origins, directions)                   # plain nearest hit per ray
    cam = Camera.look_at(eye, target, fov_y=40, aspect=4/3)
    image = cloud.render(cam, 640, 480, method=Method.preset("FULL"))

Everything heavy runs in the compiled module `_core` (BVH, intersection, threads). This
file turns numpy arrays into the contiguous float32 buffers it wants and allocates the
outputs. Coordinates are those of one local frame: a caller with georeferenced data
subtracts a float64 origin first (see `neighbours.local_frame`).
"""
from __future__ import annotations

from typing import Callable, NamedTuple, Optional, Sequence

import numpy as np

from .. import _core
from ..util.arrays import as_f32
from .camera import Camera, window_rect
from .method import Method

PARALLEL_COSINE = _core.PARALLEL_COSINE
MAX_LAYER_HITS = _core.MAX_LAYER_HITS  # per-ray hit buffer of the ε-window query
# Largest coordinate or radius magnitude the core accepts (native/base/ray.h says why); the
# export leaves out what exceeds it, and the import reads with the same limit.
MAX_COORDINATE = _core.MAX_COORDINATE
hardware_threads = _core.hardware_threads
simd_path = _core.simd_path  # 'SSE2' or 'plain floats': the BVH's box and disc tests


class TraceResult(NamedTuple):
    t: np.ndarray       # (N,) float32 distance along the normalised direction; inf on a miss
    id: np.ndarray      # (N,) int32 splat index, -1 on a miss
    front: np.ndarray   # (N,) bool, the ray meets the side the splat normal points to
    normal: Optional[np.ndarray]  # (N,3) float32 splat normal (zeros on a miss), if asked for


class SurfaceResult(NamedTuple):
    t: np.ndarray        # (N,) distance to the surface point; inf on a miss
    id: np.ndarray       # (N,) the splat whose hit is the surface point, -1 on a miss
    front: np.ndarray    # (N,) bool, facing of that hit
    normal: np.ndarray   # (N,3) shading normal (interpolated or flat); zeros on a miss
    colour: np.ndarray   # (N,3) blended colour
    members: Optional[np.ndarray]  # (N, MAX_LAYER_HITS) int32: the layer's splats, -1 padded


class RenderResult(NamedTuple):
    rgba: np.ndarray                # (h, w, 4) float32, top row first
    depth: Optional[np.ndarray]     # (h, w) planar depth along the view axis; 1e10 on background
    normal: Optional[np.ndarray]    # (h, w, 3) unit normals (an open cloud's back: turned to the camera); zeros on background
    completed: bool                 # False when progress() asked to stop


class SplatCloud:
    """Splats (oriented discs) and the BVH over them. Immutable; safe to share.

    centres (N,3), normals (N,3, any non-zero length), radii (N,) > 0 and optional colours
    (N,3, scene-linear RGB) in one local frame. closed: whether each splat belongs to a
    closed, hole-free object (bool for all, or (N,) flags; the far phase applies to those
    only). alphas: optional (N,) opacities in 0..1, the points' own alpha (a material whose
    Alpha reads them makes the cloud see-through there). Raises ValueError naming the first
    bad splat (non-finite value, zero normal, radius <= 0, alpha outside 0..1), TypeError for
    unusable arrays.
    threads: default thread count for tracing and rendering (0: all cores).
    attributes: the point attributes the scene's node programs read (Attribute node), as
    render/nodes.py attribute_columns lays them out for `attribute_layout` (the scene's
    nodes.attribute_layout: a Scene refuses a cloud laid out otherwise); blended at a hit as
    the colours are. Without them an Attribute node reads 0 here, as a missing one does.
    """

    def __init__(self, centres, normals, radii, colours=None, closed=False, threads: int = 0, alphas=None,
                 attributes=None, attribute_layout: tuple = ()):
        c = as_f32(centres, "centres", (-1, 3))
        n = as_f32(normals, "normals", (len(c), 3))
        r = as_f32(radii, "radii", (len(c),))
        col = None if colours is None else as_f32(colours, "colours", (len(c), 3))
        a = None if alphas is None else as_f32(alphas, "alphas", (len(c),))
        flags = np.broadcast_to(np.asarray(closed, dtype=np.uint8), (len(c),))
        self.attribute_layout = tuple(attribute_layout) if attributes is not None else ()
        attr = None
        if attributes is not None:
            attr = as_f32(attributes, "attributes", (len(c), sum(w for _, w in self.attribute_layout)))
        self._scene = _core.SplatCloud(c, n, r, col, np.ascontiguousarray(flags), threads, a, attr)

    def __len__(self) -> int:
        return self._scene.size

    @property
    def bounds(self):
        """((xmin, ymin, zmin), (xmax, ymax, zmax)) over every disc, or None when empty."""
        return self._scene.bounds

    def bvh_stats(self) -> dict:
        return self._scene.bvh_stats()

    def traversal_cost(self, origins, directions, tmin: float = 0.0, tmax: float = np.inf,
                       packets: bool = False) -> dict:
        """Work the BVH does for these nearest-hit rays: {'nodes': nodes entered, 'discs':
        disc tests}, summed over the rays. Tests compare costs with it instead of timings.
        packets: as in trace() (a packet's inner node counts once for all its rays)."""
        o = as_f32(origins, "origins", (-1, 3))
        d = as_f32(directions, "directions", (len(o), 3))
        n = len(o)
        stats = np.zeros(2, np.int64)
        self._scene.trace(o, d, float(tmin), float(tmax), np.empty(n, np.float32), np.empty(n, np.int32),
                          np.empty(n, np.bool_), None, 0, False, stats, packets)
        return {"nodes": int(stats[0]), "discs": int(stats[1])}

    def trace(self, origins, directions, tmin: float = 0.0, tmax: float = np.inf, normals: bool = True,
              threads: int = 0, brute_force: bool = False, packets: bool = True) -> TraceResult:
        """Nearest splat hit (either facing) per ray, in the open interval (tmin, tmax).

        Directions need not be unit length; they are normalised and `t` is a distance.
        brute_force tests every splat: the slow reference the BVH is checked against.
        packets: consecutive rays go through the tree 16 at a time when they are coherent
        (camera rays of a 4x4 pixel tile: order them so); False traces each ray alone. The
        answers are the same either way.
        """
        o = as_f32(origins, "origins", (-1, 3))
        d = as_f32(directions, "directions", (len(o), 3))
        n = len(o)
        t = np.empty(n, np.float32)
        ids = np.empty(n, np.int32)
        front = np.empty(n, np.bool_)
        nrm = np.empty((n, 3), np.float32) if normals else None
        self._scene.trace(o, d, float(tmin), float(tmax), t, ids, front, nrm, threads, brute_force, None, packets)
        return TraceResult(t, ids, front, nrm)

    def trace_surface(self, origins, directions, method: Method = Method(), tmin: float = 0.0,
                      tmax: float = np.inf, inside=None, exclude=None, members: bool = False,
                      threads: int = 0, brute_force: bool = False, packets: bool = True) -> SurfaceResult:
        """The surface each ray sees under `method`, with its shading normal and colour.

        inside: (N,) flags (or one bool) for rays travelling inside an object (refracted):
            their layer begins with a back-facing hit, the exit.
        exclude: (N, M) int32 splat ids each ray must not hit, -1 for none: a secondary ray
            (reflection, shadow, refraction) passes the `members` of the hit it starts from.
        members: also return the splats that made each surface point.
        brute_force: offer every splat to the query (the tests' reference for the BVH).
        packets: as in trace(); the first layer query of 16 coherent rays in one traversal.
        """
        o = as_f32(origins, "origins", (-1, 3))
        d = as_f32(directions, "directions", (len(o), 3))
        n = len(o)
        out = SurfaceResult(np.empty(n, np.float32), np.empty(n, np.int32), np.empty(n, np.bool_),
                            np.empty((n, 3), np.float32), np.empty((n, 3), np.float32),
                            np.empty((n, MAX_LAYER_HITS), np.int32) if members else None)
        inside_arr = None
        if inside is not None:
            inside_arr = np.ascontiguousarray(np.broadcast_to(np.asarray(inside, dtype=np.uint8), (n,)))
        ex = None
        if exclude is not None:
            raw = np.asarray(exclude)
            if raw.size and not np.issubdtype(raw.dtype, np.integer):
                raise TypeError(f"exclude must hold integer splat ids, got dtype {raw.dtype}")
            if raw.size and (raw.min() < -1 or raw.max() >= len(self)):
                raise ValueError(f"exclude holds ids outside -1..{len(self) - 1} (min {raw.min()}, max {raw.max()})")
            ex = np.ascontiguousarray(raw, dtype=np.int32)
            if ex.ndim != 2 or len(ex) != n:
                raise ValueError(f"exclude must have shape ({n}, M), got {ex.shape}")
        self._scene.trace_surface(o, d, float(tmin), float(tmax), method, out.t, out.id, out.front,
                                  out.normal, out.colour, out.members, inside_arr, ex, threads, brute_force,
                                  packets)
        return out

    def render(self, camera: Camera, width: int, height: int, window: Optional[Sequence[int]] = None,
               background: Sequence[float] = (0.0, 0.0, 0.0, 0.0), depth: bool = True, normal: bool = True,
               threads: int = 0, progress: Optional[Callable[[int, int], bool]] = None,
               tile_size: int = 32, method: Method = Method(), packets: bool = True) -> RenderResult:
        """Renders one ray per pixel centre with a headlight, the surface chosen by `method`.

        window: (x0, y0, w, h) sub-rectangle of the width x height image (x0, y0: column
        and row of its top-left pixel), default the whole image. progress(done, total) is
        called from this thread every ~50 ms; returning True stops the render. packets:
        4x4 pixels traced as one packet (False: pixel by pixel; the same image).
        """
        if camera.lens is not None:
            raise ValueError("SplatCloud.render traces one ray per pixel centre through a pinhole; a camera with a "
                             "lens (depth of field) renders through RenderScene.render, which samples the lens")
        x0, y0, w, h = window_rect(window, width, height)
        rgba = np.empty((h, w, 4), np.float32)
        dep = np.empty((h, w), np.float32) if depth else None
        nrm = np.empty((h, w, 3), np.float32) if normal else None
        done = self._scene.render(
            *camera.native(), int(width), int(height), (int(x0), int(y0), int(w), int(h)),
            tuple(float(v) for v in background), rgba, dep, nrm, threads, progress, tile_size, method,
            packets)
        return RenderResult(rgba, dep, nrm, done)
