"""The viewport's Rendered mode: Blender's view -> core camera, what a depsgraph update
changes, and a progressive session that renders into a buffer.

Everything here except `view_of` and `view_lens` (which read the 3D view and the camera) and
`update_from_depsgraph` is
plain Python over numpy and the core, and is tested headless; the engine's view_draw only
draws the session's latest buffer with the `gpu` module (engine.py).

Rendering runs on a Python thread (`ViewportSession.start`): the core releases the GIL while
it traces, so Blender's UI thread stays free; the thread never touches bpy. Everything that
reads Blender (the export, the view's matrices) happens on the main thread, in view_update
and view_draw, and hands the thread immutable snapshots (a RenderScene, a Camera, settings).
"""
from __future__ import annotations

import atexit
import math
import threading
import time
import weakref
from dataclasses import dataclass, field
from typing import Iterable, Optional

import numpy as np

from ..render import ab, shading
from ..render.camera import Camera, Lens
from ..render.method import Method
from ..render.scene import RenderScene
from ..util import matrices
from . import denoise
from .export import settings as export_settings

# --------------------------------------------------------------------------------------
# The view


def _matrix(m) -> np.ndarray:
    a = np.array([[float(v) for v in row] for row in m], dtype=np.float64) if not isinstance(m, np.ndarray) \
        else np.asarray(m, dtype=np.float64)
    if a.shape != (4, 4) or not np.isfinite(a).all():
        raise ValueError(f"a view matrix must be a finite 4x4 matrix, got shape {a.shape}")
    return a


def camera_from_view(window_matrix, view_matrix, origin=(0.0, 0.0, 0.0), clip=None, lens=None,
                     panorama=None) -> Camera:
    """The core camera of a 3D view: `window_matrix` is its projection (view space to clip
    space, RegionView3D.window_matrix) and `view_matrix` maps world to view space
    (RegionView3D.view_matrix). Perspective, orthographic and the camera view all come this
    way: Blender folds the camera's lens, sensor fit, shift, the view's zoom and its offset
    into window_matrix's x and y rows, which its float32 keeps to float precision. `clip`:
    the view's clipping range (start, end) in double, which a float32 perspective matrix
    loses for ranges of about 1e8 and more (None: read from window_matrix). `origin`: the
    scene's local-frame origin (float64 world position). `lens`: the scene camera's depth
    of field in the camera view (render.camera.Lens), None elsewhere. `panorama`: in the
    camera view of a panoramic camera, (the region's (u, v) window, render.camera.Panorama)
    (view_panorama); window_matrix then plays no part."""
    if panorama is not None:
        return Camera.from_frustum(matrices.inverse(_matrix(view_matrix)), panorama[0], clip, False, origin, lens,
                                   panorama[1])
    camera = Camera.from_view_projection(_matrix(window_matrix), matrices.inverse(_matrix(view_matrix)), origin, clip)
    return camera.with_lens(lens) if lens is not None else camera


def region_rect(perspective_matrix, world_points, width: int, height: int) -> tuple[float, float, float, float]:
    """(xmin, ymin, xmax, ymax) in region pixels (origin bottom left, as Blender's region
    coordinates) of world points projected by `perspective_matrix` (window @ view): used for
    the camera frame in the camera view."""
    p = _matrix(perspective_matrix)
    pts = np.column_stack([np.asarray(world_points, np.float64).reshape(-1, 3), np.ones(len(world_points))])
    clip = pts @ p.T
    ndc = clip[:, :2] / clip[:, 3:4]
    x = (ndc[:, 0] + 1.0) * 0.5 * width
    y = (ndc[:, 1] + 1.0) * 0.5 * height
    return float(x.min()), float(y.min()), float(x.max()), float(y.max())


def border_window(width: int, height: int, rect=None, fractions=None) -> Optional[tuple[int, int, int, int]]:
    """The rendered window (x0, y0 from the top, w, h) of a width x height region.

    rect: (xmin, ymin, xmax, ymax) region pixels (bottom-left origin) the border fractions
    are relative to (the camera frame in the camera view; default the region); fractions:
    (min_x, min_y, max_x, max_y) of the border, or None for no border (the whole region).
    None when the border lies outside the region or the region has no pixels (nothing to
    render)."""
    if width <= 0 or height <= 0:
        return None
    if fractions is None:
        return 0, 0, width, height
    rx0, ry0, rx1, ry1 = rect if rect is not None else (0.0, 0.0, float(width), float(height))
    fx0, fy0, fx1, fy1 = fractions
    # Blender rounds border edges to the nearest pixel.
    x0 = int(np.floor(rx0 + fx0 * (rx1 - rx0) + 0.5))
    x1 = int(np.floor(rx0 + fx1 * (rx1 - rx0) + 0.5))
    yb0 = int(np.floor(ry0 + fy0 * (ry1 - ry0) + 0.5))
    yb1 = int(np.floor(ry0 + fy1 * (ry1 - ry0) + 0.5))
    x0, x1 = max(x0, 0), min(x1, width)
    yb0, yb1 = max(yb0, 0), min(yb1, height)
    if x1 <= x0 or yb1 <= yb0:
        return None
    return x0, height - yb1, x1 - x0, yb1 - yb0


@dataclass(frozen=True)
class View:
    """What the viewport shows: its matrices (nested tuples or arrays), region size, the
    rendered window (None: an empty border, nothing rendered), the clipping range
    (start, end) in double (None: read from window_matrix) and the lens (the scene
    camera's depth of field in the camera view, as Cycles' viewport has it; None: a
    pinhole). A change of any of them renders again."""

    window_matrix: tuple
    view_matrix: tuple
    width: int
    height: int
    window: Optional[tuple] = None
    clip: Optional[tuple] = None
    lens: Optional[Lens] = None
    panorama: Optional[tuple] = None  # view_panorama's, in the camera view of a panoramic camera

    @classmethod
    def of(cls, window_matrix, view_matrix, width: int, height: int, window="ALL", clip=None, lens=None,
           panorama=None) -> "View":
        as_tuple = lambda m: tuple(tuple(float(v) for v in row) for row in _matrix(m))
        if window == "ALL":
            window = border_window(int(width), int(height))
        clip = None if clip is None else (float(clip[0]), float(clip[1]))
        return cls(as_tuple(window_matrix), as_tuple(view_matrix), int(width), int(height), window, clip, lens,
                   panorama)


def view_panorama(cam, render, frame_rect, width: int, height: int) -> Optional[tuple]:
    """The camera view of a panoramic camera as Cycles' viewport shows it: the panorama
    fills the camera frame (frame_rect: xmin, ymin, xmax, ymax in region pixels), and the
    region around it continues it. (The region's (u, v) window, render.camera.Panorama),
    or None for a perspective or orthographic camera and for the panorama types the engine
    does not render (the camera view then shows the camera's perspective view, as before;
    F12 names the type)."""
    from . import export
    if cam.data.type != "PANO":
        return None
    try:
        (u0, u1, v0, v1), panorama = export.camera_panorama(cam, render.resolution_x, render.resolution_y,
                                                           render.pixel_aspect_x, render.pixel_aspect_y)
    except RuntimeError:
        return None
    x0, y0, x1, y1 = frame_rect
    if not (x1 > x0 and y1 > y0):
        return None
    # The region's edges in the frame's (u, v), the frame spanning the (shifted) unit square.
    fu, fv = (u1 - u0) / (x1 - x0), (v1 - v0) / (y1 - y0)
    return (u0 - x0 * fu, u0 + (width - x0) * fu, v0 - y0 * fv, v0 + (height - y0) * fv), panorama


def view_clip(scene, depsgraph, rv3d, space) -> Optional[tuple]:
    """The clipping range of a 3D view, from its parameters: the camera's in the camera
    view, the View3D's in a perspective view. None for an orthographic view: Blender
    centres its range on the view (-clip_end/2 to clip_end/2), and an orthographic
    matrix keeps its range (it divides by no w), so window_matrix gives it."""
    if rv3d.view_perspective == "CAMERA" and scene.camera is not None:
        data = scene.camera.evaluated_get(depsgraph).data
        return (data.clip_start, data.clip_end) if scene.camera.type == "CAMERA" else None
    if rv3d.is_perspective:
        return (space.clip_start, space.clip_end)
    return None


def view_of(scene, depsgraph, region, rv3d, space) -> View:
    """The View of a 3D viewport (main thread: reads bpy). The border is the View3D's render
    border, or in the camera view the scene's render border within the camera frame."""
    width, height = int(region.width), int(region.height)
    window_matrix, view_matrix = rv3d.window_matrix, rv3d.view_matrix
    panorama = None
    if rv3d.view_perspective == "CAMERA" and scene.camera is not None:
        fractions = None
        cam = scene.camera.evaluated_get(depsgraph)
        frame = [cam.matrix_world @ v for v in cam.data.view_frame(scene=scene)] if cam.type == "CAMERA" else []
        rect = region_rect(rv3d.perspective_matrix, [tuple(v) for v in frame], width, height) if frame else None
        if rect is not None:
            panorama = view_panorama(cam, scene.render, rect, width, height)
        if scene.render.use_border:
            r = scene.render
            fractions = (r.border_min_x, r.border_min_y, r.border_max_x, r.border_max_y)
        else:
            rect = None
    else:
        rect = None
        fractions = ((space.render_border_min_x, space.render_border_min_y, space.render_border_max_x,
                      space.render_border_max_y) if space.use_render_border else None)
    return View.of(window_matrix, view_matrix, width, height, border_window(width, height, rect, fractions),
                   view_clip(scene, depsgraph, rv3d, space), view_lens(scene, depsgraph, rv3d), panorama)


def view_lens(scene, depsgraph, rv3d) -> Optional[Lens]:
    """The depth of field a 3D view renders: the scene camera's in the camera view (as
    Cycles' viewport does), none in any other view."""
    from . import export
    if rv3d.view_perspective != "CAMERA" or scene.camera is None or scene.camera.type != "CAMERA":
        return None
    return export.camera_lens(scene.camera.evaluated_get(depsgraph), depsgraph)


# --------------------------------------------------------------------------------------
# What changed

# Datablock types (the RNA type names of depsgraph.updates' ids) and what their change asks for.
_GEOMETRY = {"Mesh", "PointCloud", "Curve", "Curves", "TextCurve", "SurfaceCurve", "MetaBall", "GeometryNodeTree",
             "Lattice"}
_SHADING = {"Material", "ShaderNodeTree", "World", "Image", "Texture", "Light", "PointLight", "SunLight",
            "SpotLight", "AreaLight"}
_NOTHING = {"Camera", "Screen", "WindowManager", "Workspace", "WorkSpace", "Brush", "Palette", "Text"}


@dataclass
class Changes:
    """What a depsgraph update asks of the viewport session. export: the scene is exported
    again (its geometry comes from the cache: only a changed object's is rebuilt; lamps,
    materials and transforms are cheap); settings: the scene's settings are read again (a
    method switch, epsilon, samples: re-rendered without export, unless the radius factor or
    the frame changed). The view is not an update: view_draw compares the matrices."""

    export: bool = False
    settings: bool = False
    reasons: list = field(default_factory=list)

    @classmethod
    def everything(cls) -> "Changes":
        return cls(True, True, ["first update"])

    def __bool__(self) -> bool:
        return self.export or self.settings


def classify(updates: Iterable) -> Changes:
    """Changes from `depsgraph.updates` (records with .id, .is_updated_geometry,
    .is_updated_transform, .is_updated_shading)."""
    changes = Changes()
    for u in updates:
        block = u.id
        kind = type(block).__name__
        if kind == "Object":
            if block.type == "CAMERA":
                continue  # the view's matrices say what the camera view sees
            flags = [f for f in ("geometry", "transform", "shading") if getattr(u, f"is_updated_{f}")]
            if block.type == "LIGHT" and flags:
                changes.export = True
                changes.reasons.append(f"lamp '{block.name}'")
            elif flags:
                changes.export = True
                changes.reasons.append(f"object '{block.name}' ({', '.join(flags)})")
        elif kind == "Scene":
            changes.settings = True
            changes.reasons.append("scene settings")
        elif kind in _NOTHING:
            continue
        elif kind in _SHADING:
            changes.export = True
            changes.reasons.append(f"{kind.lower()} '{block.name}'")
        elif kind in _GEOMETRY or kind == "Collection":
            changes.export = True
            changes.reasons.append(f"{kind.lower()} '{block.name}'")
        else:  # unknown: export again (the cache keeps it cheap)
            changes.export = True
            changes.reasons.append(f"{kind} '{getattr(block, 'name', '?')}'")
    return changes


# --------------------------------------------------------------------------------------
# Progressive rendering

COARSE_SCALE = 4   # the first pass: 1 sample at 1/COARSE_SCALE of the resolution (at least), upscaled
GROWTH = 4         # each later pass renders GROWTH times the samples of the one before
# Pixels of the first pass at most (its divisor grows with the view): on the demo scene
# (benchmarks/viewport_latency.py) 1 lit sample of 20,000 pixels takes about 50 ms on 2
# cores, which keeps the first image within issue 13's ~100 ms of a change.
COARSE_PIXELS = 20_000


def pass_schedule(samples: int, coarse_scale: int = COARSE_SCALE, pixels: int = 0) -> list[tuple[int, int]]:
    """(resolution divisor, samples) of each pass: a coarse pass, then full resolution with
    1, 4, 16, ... samples up to `samples`. Each pass is a complete render from scratch, so
    the last one is the F12 image (same samples, same seed): the core numbers a pixel's
    samples from 0 and has no sample offset, so passes cannot be accumulated exactly (see
    the README); the repeated work is at most 1/(GROWTH-1) of the last pass.

    pixels: the window's size. A large view's coarse pass is divided further, to at most
    COARSE_PIXELS, and halved divisors follow it while a pass would still be four times
    that or more (1280x720: 1/7, 1/3, then full resolution), so that a picture comes within
    ~100 ms and sharpens before the first full-resolution pass."""
    if coarse_scale > 1 and pixels > 0:
        coarse_scale = max(coarse_scale, math.ceil(math.sqrt(pixels / COARSE_PIXELS)))
    out = [(coarse_scale, 1)] if coarse_scale > 1 else []
    scale = coarse_scale // 2
    while scale > 1 and pixels / (scale * scale) >= 4 * COARSE_PIXELS:
        out.append((scale, 1))
        scale //= 2
    s = 1
    while True:
        out.append((1, s))
        if s >= samples:
            return out
        s = min(samples, s * GROWTH)


def _window_pixels(view: View) -> int:
    """The pixels a pass of this view renders at full resolution (its border window's)."""
    return 0 if view.window is None else int(view.window[2]) * int(view.window[3])


# One variant's progressive render as the render thread takes it: immutable inputs built on
# the main thread (the thread never touches bpy) and the passes' schedule. Not a
# progress.Job, which runs one piece of work on a thread of its own that the main thread
# polls: the session's single render thread works through these, a pass at a time.
@dataclass(frozen=True)
class _VariantRender:
    generation: int
    variant: str
    render_scene: RenderScene
    camera: Camera
    view: View
    settings: shading.RenderSettings
    method: Method
    threads: int
    schedule: tuple
    denoising: Optional[object] = None  # export/settings.py Denoising: the last pass is denoised


def _scaled_window(window, width, height, lw, lh):
    x0, y0, w, h = window
    a0, a1 = (x0 * lw) // width, -((-(x0 + w) * lw) // width)
    b0, b1 = (y0 * lh) // height, -((-(y0 + h) * lh) // height)
    a1, b1 = max(min(a1, lw), a0 + 1), max(min(b1, lh), b0 + 1)
    return a0, b0, a1 - a0, b1 - b0


def render_pass(job: _VariantRender, index: int, progress=None) -> Optional[np.ndarray]:
    """Pass `index` of the job as a (height, width, 4) region buffer, top row first,
    transparent outside the window; None when progress() stopped it."""
    scale, samples = job.schedule[index]
    v = job.view
    out = np.zeros((v.height, v.width, 4), np.float32)
    if v.window is None:
        return out
    settings = shading.RenderSettings(**{**job.settings.__dict__, "samples": samples})
    if scale == 1:
        x0, y0, w, h = v.window
        d = job.denoising if index == len(job.schedule) - 1 else None
        passes = ("Combined",) + (("DiffCol",) if d is not None and d.albedo else ()) + \
            (("Normal",) if d is not None and d.normal else ())
        result = job.render_scene.render(job.camera, v.width, v.height, settings, job.method, passes,
                                         window=v.window, threads=job.threads, progress=progress)
        if not result.completed:
            return None
        combined = result.passes["Combined"]
        if d is not None:
            # Cycles' viewport denoising, at the last pass only (each earlier pass would pay
            # the denoiser's fraction of a second again); the normal stays in world space,
            # which OIDN takes as well as camera space.
            combined = combined.copy()
            combined[..., :3] = denoise.denoise(combined, result.passes.get("DiffCol"), result.passes.get("Normal"),
                                                d.prefilter, d.quality, job.threads)
        out[y0:y0 + h, x0:x0 + w] = combined
        return out
    lw, lh = max(1, -(-v.width // scale)), max(1, -(-v.height // scale))
    lx, ly, lww, lhh = _scaled_window(v.window, v.width, v.height, lw, lh)
    result = job.render_scene.render(job.camera, lw, lh, settings, job.method, ("Combined",),
                                     window=(lx, ly, lww, lhh), threads=job.threads, progress=progress)
    if not result.completed:
        return None
    low = np.zeros((lh, lw, 4), np.float32)
    low[ly:ly + lhh, lx:lx + lww] = result.passes["Combined"]
    rows = np.minimum(((np.arange(v.height) + 0.5) * lh / v.height).astype(int), lh - 1)
    cols = np.minimum(((np.arange(v.width) + 0.5) * lw / v.width).astype(int), lw - 1)
    x0, y0, w, h = v.window
    out[y0:y0 + h, x0:x0 + w] = low[rows[y0:y0 + h]][:, cols[x0:x0 + w]]
    return out


@dataclass(frozen=True)
class Image:
    """A finished pass: the buffer and what it is."""

    pixels: np.ndarray      # (height, width, 4) float32, premultiplied scene-linear, top row first
    view: View
    generation: int
    index: int              # pass index in the schedule
    samples: int
    scale: int
    final: bool             # the last pass: the F12 image of this view (with this variant's settings)
    variant: str = "SCENE"  # 'SCENE', or 'A' / 'B' (the live A/B comparison)
    denoised: bool = False  # the last pass, denoised (Cycles' viewport Denoise)


def variants_of(props) -> tuple:
    """What the viewport renders for a scene's settings (scene.splat_tracer): the scene's
    own settings, or with A/B on (any mode but Off) both A and B, so that flipping between
    them or splitting the view never waits for a render."""
    if props.ab.mode == "OFF":
        return (ab.Variant("SCENE", props.core_method(), float(props.radius_factor)),)
    return tuple(ab.Variant(name, slot.core_method(), float(slot.radius_factor))
                 for name, slot in (("A", props.ab.a), ("B", props.ab.b)))


class ViewportSession:
    """The viewport's persistent state: the exported scene (kept between redraws), its
    geometry cache, the settings, the view, and the progressive passes of each variant (the
    scene's settings, or A and B).

    Main thread: update(depsgraph, changes) after a depsgraph update, set_view(view) on each
    redraw, latest() / snapshot() to draw. Rendering: step() renders the next pass
    synchronously (tests), or start() runs the passes on a thread. The variants' passes
    interleave (A's pass 0, B's pass 0, A's pass 1, ...). counters: exports (export_scene
    calls: one per radius factor in use), geometry_builds (BVHs built), renders (core render
    calls = passes), restarts (a variant's refinement started over)."""

    def __init__(self, coarse_scale: int = COARSE_SCALE):
        from .session import GeometryCache
        self.cache = GeometryCache()
        self.coarse_scale = coarse_scale
        self.counters = dict(exports=0, geometry_builds=0, renders=0, restarts=0)
        self.report = shading.Report()
        self.origin: Optional[np.ndarray] = None
        self.exports: dict = {}     # radius factor -> ExportedScene
        self._export_state = None   # (frame, world, visible objects, radius factors) of the exports
        self._variants: tuple = ()
        self._states: dict = {}     # variant name -> (variant, settings, threads, render scene) of its job
        self._view: Optional[View] = None
        self._camera: Optional[Camera] = None
        self._cond = threading.Condition()
        self._jobs: dict = {}       # variant name -> _VariantRender
        self._next: dict = {}       # variant name -> its next pass
        self._generation = 0
        self._images: dict = {}     # variant name -> its latest Image
        self._version = 0           # counts the images stored
        self._thread: Optional[threading.Thread] = None
        self._closed = False
        self.error: Optional[str] = None

    @property
    def exported(self):
        """The exported scene of the first variant (None before the first update)."""
        if not self._variants:
            return None
        return self.exports.get(self._variants[0].radius_factor)

    @property
    def variants(self) -> tuple:
        return self._variants

    # -- main thread ------------------------------------------------------------------
    def update(self, depsgraph, changes: Optional[Changes] = None) -> None:
        """Reads what `changes` says changed (everything when None or on the first call)."""
        from . import export
        from .export import shading as export_shading
        from .session import lit_settings
        if changes is None or self.exported is None:
            changes = Changes.everything()
        if not changes:
            return
        scene = depsgraph.scene
        props = scene.splat_tracer
        variants = variants_of(props)
        factors = tuple(sorted({v.radius_factor for v in variants}))
        # A Scene-only update also comes for hiding an object or assigning another world:
        # what the export depends on besides the datablocks is compared (cheap: no arrays).
        # The radius factor is baked into the clouds' splats: each factor in use is its own
        # export, whose clouds are built for it (meshes are shared through the cache).
        export_state = (int(scene.frame_current), scene.world.name_full if scene.world is not None else None,
                        tuple(sorted(o.name_full for o in depsgraph.objects)), factors)
        exported_now = changes.export or export_state != self._export_state
        if exported_now:
            if self.origin is None:
                # Fixed for the session: the instances are placed relative to it, so that a
                # new view never needs a new export. The scene camera's, as F12 uses.
                self.origin = export.camera_origin(depsgraph)
            report = shading.Report()
            exports = {}
            self.cache.begin_frame()  # one cache frame for every factor: none drops another's geometry
            try:
                for factor in factors:
                    exports[factor] = export.export_scene(depsgraph, self.cache, self.origin, factor,
                                                          scene.render.threads, report)
            except BaseException:
                self.cache.end_frame(keep=False)
                raise
            self.cache.end_frame(keep=True)
            self.counters["exports"] += len(factors)
            self.counters["geometry_builds"] += self.cache.built
            self.exports, self.report, self._export_state = exports, report, export_state
        self._variants = variants
        first = self.exports[variants[0].radius_factor]
        settings, _ = lit_settings(scene, first, export_shading.render_settings_of(scene, viewport=True), None,
                                    self.report)
        threads = int(scene.render.threads)
        # Viewport denoising for the scene's own image only: the A/B variants compare the
        # methods' surfaces, which a denoiser would smooth alike.
        denoising = export_settings.denoising_of(scene, depsgraph.view_layer, viewport=True) \
            if denoise.available() else None
        states = {v.name: (v, settings, threads, id(self.exports[v.radius_factor].render_scene),
                           denoising if v.name == "SCENE" else None) for v in variants}
        stale = [name for name, state in states.items() if exported_now or self._states.get(name) != state]
        self._states = states
        with self._cond:
            for name in set(self._jobs) - set(states):  # a variant no longer shown
                del self._jobs[name]
                self._images.pop(name, None)
        if stale:
            self._restart(stale)

    def set_view(self, view: View) -> None:
        if view != self._view:
            self._view = view
            self._camera = None
            self._restart()

    def latest(self, variant: Optional[str] = None) -> Optional[Image]:
        """The newest image of a variant (default: the first)."""
        with self._cond:
            if variant is None:
                variant = self._variants[0].name if self._variants else "SCENE"
            return self._images.get(variant)

    def snapshot(self) -> tuple[dict, int]:
        """({variant: newest Image}, version): version grows with each image stored."""
        with self._cond:
            return dict(self._images), self._version

    @property
    def generation(self) -> int:
        """Counts the restarts: an Image of an older generation shows an older state."""
        with self._cond:
            return self._generation

    @property
    def done(self) -> bool:
        """Whether every variant's last pass is finished (or nothing is to be rendered)."""
        with self._cond:
            return self._finished()

    # -- the passes ---------------------------------------------------------------------
    def _restart(self, names=None) -> None:
        """Starts the refinement of these variants (default all) over."""
        if not self.exports or self._view is None or not self._states:
            return
        self.error = None
        if self._camera is None and self._view.window is not None:  # no window: no rays (render_pass)
            self._camera = camera_from_view(self._view.window_matrix, self._view.view_matrix, self.origin,
                                            self._view.clip, self._view.lens, self._view.panorama)
        with self._cond:
            for name in names if names is not None else list(self._states):
                variant, settings, threads, _, denoising = self._states[name]
                self._generation += 1
                self._jobs[name] = _VariantRender(
                    self._generation, name, self.exports[variant.radius_factor].render_scene, self._camera,
                    self._view, settings, variant.method, threads,
                    tuple(pass_schedule(settings.samples, self.coarse_scale, _window_pixels(self._view))), denoising)
                self._next[name] = 0
                self.counters["restarts"] += 1
            self._cond.notify_all()

    def _work(self) -> Optional[tuple[_VariantRender, int]]:
        """The next pass to render: the variant furthest behind (in variant order on a tie)."""
        with self._cond:
            order = [v.name for v in self._variants if v.name in self._jobs]
            pending = [(self._next[n], i, n) for i, n in enumerate(order)
                       if self._next[n] < len(self._jobs[n].schedule)]
            if not pending:
                return None
            _, _, name = min(pending)
            return self._jobs[name], self._next[name]

    def _current(self, job: _VariantRender) -> bool:
        return self._jobs.get(job.variant) is job

    def _run(self, job: _VariantRender, index: int) -> None:
        def stop(done, total):
            return self._closed or not self._current(job)
        pixels = render_pass(job, index, stop)
        with self._cond:
            self.counters["renders"] += 1
            if pixels is None or not self._current(job):
                return
            scale, samples = job.schedule[index]
            final = index == len(job.schedule) - 1
            self._images[job.variant] = Image(pixels, job.view, job.generation, index, samples, scale, final,
                                              job.variant, final and scale == 1 and job.denoising is not None)
            self._version += 1
            self._next[job.variant] = index + 1

    def step(self) -> bool:
        """Renders the next pass here; True while more passes remain."""
        work = self._work()
        if work is not None:
            self._run(*work)
        return not self.done

    def refine(self) -> Optional[Image]:
        """Renders every remaining pass here; the first variant's last image."""
        while self.step():
            pass
        return self.latest()

    def start(self) -> None:
        """Renders the passes on a thread from now on (it never calls bpy)."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._loop, name="splat_tracer viewport", daemon=True)
            _running.add(self)
            self._thread.start()

    def _loop(self) -> None:
        while True:
            with self._cond:
                while not self._closed and self._finished():
                    self._cond.wait()
                if self._closed:
                    return
            work = self._work()
            if work is None:
                continue
            try:
                self._run(*work)
            except Exception as e:  # noqa: BLE001 - shown by view_draw; never kills Blender
                with self._cond:
                    job = work[0]
                    if self._current(job):  # give up on this variant until the next change
                        self.error = str(e)
                        self._next[job.variant] = len(job.schedule)
                time.sleep(0.01)

    def _finished(self) -> bool:
        """Whether nothing is left to render (the caller holds the lock)."""
        return all(self._next[name] >= len(job.schedule) for name, job in self._jobs.items())

    def close(self) -> None:
        """Stops the thread: the pass in flight stops within a sample of a 4x4 block (the
        core checks its stop flag between samples), so the join returns in well under its
        timeout."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)
        self._thread = None
        _running.discard(self)


# The sessions whose thread runs, closed at exit before Python finalizes: an engine's
# __del__, which closes its session, may come only during finalization or never, when the
# thread can no longer take the GIL to see the close.
_running: "weakref.WeakSet[ViewportSession]" = weakref.WeakSet()


@atexit.register
def _close_running_sessions() -> None:
    for vs in list(_running):
        vs.close()


def status(images: dict, done: bool) -> str:
    """The viewport's status line for {variant: newest Image}."""
    def one(image: Image) -> str:
        text = f"{image.samples} sample{'s' if image.samples > 1 else ''}"
        return text + (f" at 1/{image.scale} resolution" if image.scale > 1 else "") + \
            (", denoised" if image.denoised else "")
    parts = [one(images["SCENE"])] if "SCENE" in images else [f"{name}: {one(images[name])}" for name in ("A", "B")
                                                              if name in images]
    return "Splat Tracer | " + ", ".join(parts) + ("" if done else " | refining")


def update_from_depsgraph(session: ViewportSession, depsgraph, first: bool = False) -> Changes:
    """view_update's work (main thread): what changed, told to the session."""
    changes = Changes.everything() if first else classify(depsgraph.updates)
    session.update(depsgraph, changes)
    return changes
