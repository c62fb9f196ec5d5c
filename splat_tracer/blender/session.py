"""The render session: what survives from one frame to the next, and the frame render that F12,
`blender -b -a` and the A/B compare operator share.

Geometry (each cloud's and mesh's BVH) is kept in a cache keyed by its content, so a frame
in which only the camera, lamps, materials or transforms changed builds no acceleration
structure: only the small top-level tree over the instances. Like Cycles' Persistent Data,
the cache is kept after a render only when the scene asks for it (Render > Performance >
Persistent Data) or during an animation render; otherwise it is freed at once.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Callable, Optional

import numpy as np

from ..render import shading
from ..render.method import Method
from . import export
from .export import settings as export_settings
from .export import shading as export_shading


class GeometryCache:
    """Built geometry by content key. `get` returns (geometry, built_now)."""

    def __init__(self):
        self.entries: dict = {}
        self.used: set = set()
        self.counted: set = set()  # keys whose size was counted in this frame's totals
        self.built = self.reused = 0
        self.build_seconds = 0.0

    def begin_frame(self) -> None:
        self.used, self.counted = set(), set()
        self.built = self.reused = 0
        self.build_seconds = 0.0

    def get(self, key, build: Callable):
        if key in self.entries:
            if key not in self.used:
                self.reused += 1
            self.used.add(key)
            return self.entries[key], False
        t0 = time.perf_counter()
        geometry = build()
        self.build_seconds += time.perf_counter() - t0
        self.entries[key] = geometry
        self.used.add(key)
        self.built += 1
        return geometry, True

    def end_frame(self, keep: bool) -> None:
        """Drops what this frame did not use (an object deleted or changed), or everything
        when the session is not to be kept."""
        if not keep:
            self.entries.clear()
        else:
            self.entries = {k: v for k, v in self.entries.items() if k in self.used}


CACHE = GeometryCache()


def release_after_job(scene) -> None:
    """At the end of a render job (F12, or the last frame of an animation; also when one
    is cancelled): frees the geometry unless the scene keeps it (Persistent Data). Each
    frame of an animation keeps its geometry for the next one, and only the job's end
    knows that no next frame comes: without this, an animation's BVHs stayed in memory
    until the next render."""
    if scene is None or not scene.render.use_persistent_data:
        CACHE.entries.clear()


HISTORY: list = []  # stats of the frames rendered in this Blender session, newest last (tests read it)
_HISTORY_LIMIT = 100


@dataclass
class Frame:
    passes: dict            # pass name -> (h, w[, c]) float32, top row first
    completed: bool
    window: tuple           # (x0, y0 from the top, w, h) within the width x height frame
    width: int
    height: int
    stats: dict
    report: shading.Report = field(default_factory=shading.Report)


def image_size(render) -> tuple[int, int]:
    """Output size in pixels after the resolution percentage, as Blender computes it."""
    scale = render.resolution_percentage / 100.0
    return max(1, int(render.resolution_x * scale)), max(1, int(render.resolution_y * scale))


def border_window(render, width: int, height: int) -> tuple[int, int, int, int]:
    """(x0, y0 from the top, w, h) of the rendered region: the border when one is set."""
    if not render.use_border:
        return 0, 0, width, height
    # The region must be the one Blender allocates the result for (render_init_from_main:
    # `disprect.xmin = rd->border.xmin * winx`): a float32 product truncated to an int, not
    # rounded -- rounding gave a border near the top-right pixel one more pixel than
    # Blender's result holds, and the frame failed. Blender refuses a region under one
    # pixel ("Image too small") before the engine runs; the compare operator does not, so
    # a region is at least one pixel, inside the image.
    def edges(lo, hi, size):
        a, b = (int(np.float32(v) * np.float32(size)) for v in (lo, hi))
        a = min(max(a, 0), size - 1)
        return a, min(max(b, a + 1), size)

    x0, x1 = edges(render.border_min_x, render.border_max_x, width)
    yb0, yb1 = edges(render.border_min_y, render.border_max_y, height)
    return x0, height - yb1, x1 - x0, yb1 - yb0


def lit_settings(scene, exported, settings: shading.RenderSettings, headlight: Optional[bool],
                 report: shading.Report) -> tuple[shading.RenderSettings, bool]:
    """(settings, headlight) as the frame is lit. headlight: None follows the scene's Lighting
    setting, falling back to the headlight (said in the report) when nothing in the exported
    scene gives light; True/False force it. F12 and the viewport share this."""
    world = exported.render_scene.world
    lit = exported.lights > 0 or exported.emission or max(world.radiance()) > 0
    if headlight is None:
        headlight = scene.splat_tracer.lighting == "HEADLIGHT"
        if not headlight and not lit:
            headlight = True
            report.once("the scene has no lamp, no emission and a black world: rendered with a headlight "
                        "(Splat Tracer > Lighting)")
    if headlight:
        settings = replace(settings, headlight=True)
        if exported.render_scene.shadow_catchers:
            report.once("the headlight casts no shadow: shadow catchers are left out of the image entirely")
    return settings, bool(headlight)


def sampling_summary(settings: shading.RenderSettings, counters: dict, pixels: int) -> str:
    """What the render report says of the samples: how many a pixel took on average when
    adaptive sampling stopped pixels early (and the share saved), and where a time limit
    cut; empty when every pixel took every sample."""
    parts = []
    taken, reached = counters.get("samples_taken", 0), counters.get("samples_reached", settings.samples)
    if counters.get("time_limited"):
        parts.append(f"time limit {settings.time_limit:g} s reached after {reached} of {settings.samples} samples")
    if settings.adaptive and pixels and taken < settings.samples * pixels and not counters.get("time_limited"):
        mean = taken / pixels
        parts.append(f"adaptive sampling: {mean:.1f} samples per pixel on average, of {settings.samples} "
                     f"({100.0 * (1.0 - mean / settings.samples):.0f} % saved)")
    return "; ".join(parts)


def render_frame(depsgraph, method: Method, passes=("Combined",), progress=None, stats=None,
                 use_border: bool = True, headlight: Optional[bool] = None, keep: bool = False,
                 settings: Optional[shading.RenderSettings] = None) -> Frame:
    """Exports the depsgraph's view layer and renders the frame (or its border) with
    `method`. headlight: None follows the scene's Lighting setting (and falls back to the
    headlight, said in the report, when nothing in the scene gives light); True/False
    force it. keep: keep the geometry for the next frame."""
    scene = depsgraph.scene
    props = scene.splat_tracer
    width, height = image_size(scene.render)
    x0, y0, w, h = border_window(scene.render, width, height) if use_border else (0, 0, width, height)
    threads = scene.render.threads
    say = stats or (lambda s: None)
    report = shading.Report()

    t0 = time.perf_counter()
    say("Splat Tracer | exporting")
    CACHE.begin_frame()
    try:
        origin = export.camera_origin(depsgraph)
        camera = export.export_camera(depsgraph, width, height, origin)
        export_settings.report_unhonoured(scene, depsgraph.view_layer, report)
        exported = export.export_scene(depsgraph, CACHE, origin, props.radius_factor, threads, report)
    except BaseException:
        CACHE.end_frame(keep=False)
        raise
    t_export = time.perf_counter() - t0
    settings, headlight = lit_settings(scene, exported, settings or export_shading.render_settings_of(scene),
                                       headlight, report)
    summary = (f"Splat Tracer | {exported.instances} instances of {len(CACHE.used)} geometries "
               f"({exported.splats:,} splats, {exported.triangles:,} triangles), {exported.lights} lamps")
    say(summary + " | rendering")
    t1 = time.perf_counter()
    aovs = []
    for name, kind in export_shading.view_layer_aovs(depsgraph.view_layer).items():
        if name in shading.PASSES or name in passes:
            report.once(f"view layer '{depsgraph.view_layer.name}': the Shader AOV '{name}' has the name of a pass "
                        "the engine writes; it is not written")
        else:
            aovs.append((name, kind))
    result = exported.render_scene.render(camera, width, height, settings, method, passes, window=(x0, y0, w, h),
                                          threads=threads, progress=progress, aovs=aovs,
                                          aov_alpha_threshold=depsgraph.view_layer.pass_alpha_threshold)
    t_render = time.perf_counter() - t1
    position = result.passes.get("Position")
    if position is not None:
        # The core's positions are in the local frame; the pass is in world space, as
        # Cycles'. A miss stays 0 (Cycles' value there); a hit is never at the local origin,
        # which is the camera's own position.
        hit = np.any(position != 0.0, axis=-1)
        position[hit] = (position[hit] + exported.origin).astype(np.float32)
    frame_stats = dict(instances=exported.instances, geometries=len(CACHE.used), built=CACHE.built,
                       reused=CACHE.reused, build_seconds=CACHE.build_seconds, export_seconds=t_export,
                       clouds=exported.clouds, closed_clouds=exported.closed_clouds,
                       render_seconds=t_render, splats=exported.splats, triangles=exported.triangles,
                       lights=exported.lights, headlight=bool(headlight), frame=scene.frame_current,
                       view_layer=depsgraph.view_layer.name, samples=settings.samples, report=list(report.lines),
                       completed=result.completed,
                       sampling=sampling_summary(settings, result.counters, w * h),
                       **result.counters)
    CACHE.end_frame(keep)
    HISTORY.append(frame_stats)
    del HISTORY[:-_HISTORY_LIMIT]
    say(f"{summary} | built {CACHE.built}, reused {CACHE.reused} ({CACHE.build_seconds:.2f} s) | "
        f"export {t_export:.2f} s, render {t_render:.2f} s")
    return Frame(result.passes, result.completed, (x0, y0, w, h), width, height, frame_stats, report)
