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

from ..render import cryptomatte, shading
from ..render.method import Method
from . import denoise, export
from .export import motion as export_motion
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
    views: dict = field(default_factory=dict)  # a multi-view render's passes by view name ('passes': the first's)
    metadata: dict = field(default_factory=dict)  # the render result's (Cryptomatte's manifests): field -> text


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


# The core's passes the denoiser's guides are made from (Cycles' Denoising Albedo, Normal, Depth).
_GUIDES = {export_settings.DENOISING_ALBEDO: "DiffCol", export_settings.DENOISING_NORMAL: "Normal",
           export_settings.DENOISING_DEPTH: "Depth"}


def denoise_passes(passes: dict, wanted, denoising, world_from_camera, threads: int,
                   report: shading.Report) -> dict:
    """The frame's passes with Cycles' denoising applied: Combined denoised by OIDN (its
    alpha kept), the noisy Combined as "Noisy Image", the guides as Cycles names them --
    Denoising Albedo (the first hit's diffuse albedo: the Diffuse Color pass), Denoising
    Normal (the Normal pass in camera space, as Cycles writes it), Denoising Depth (the
    Depth pass) -- each kept only when `wanted`. denoising: export/settings.py's Denoising,
    or None (the image is not denoised, the guides are still written when wanted)."""
    out = {name: pixels for name, pixels in passes.items() if name in wanted}
    normal = passes.get("Normal")
    if normal is not None:
        # world -> camera: the rows of R^T, i.e. n @ R for row vectors; then Cycles' camera
        # space, which looks down +Z (Blender's down -Z): z negated.
        rotation = np.asarray(world_from_camera, dtype=np.float64)[:3, :3]
        rotation = rotation / np.maximum(np.linalg.norm(rotation, axis=0), 1e-30)
        normal = (normal.astype(np.float64) @ rotation * (1.0, 1.0, -1.0)).astype(np.float32)
    # Each guide from its core pass (_GUIDES), the Normal turned into Cycles' camera space.
    guides = {name: normal if source == "Normal" else passes.get(source) for name, source in _GUIDES.items()}
    for name, pixels in guides.items():
        if name in wanted and pixels is not None:
            out[name] = pixels
    if denoising is None:
        return out
    combined = passes["Combined"]
    if export_settings.NOISY_IMAGE in wanted:
        out[export_settings.NOISY_IMAGE] = combined.copy()
    if not denoise.available():
        report.once("Denoise: Blender's OpenImageDenoise library was not found, the image is not denoised")
        return out
    try:
        albedo = guides[export_settings.DENOISING_ALBEDO] if denoising.albedo else None
        clean = denoise.denoise(combined[..., :3], albedo, normal if denoising.normal else None, denoising.prefilter, denoising.quality, threads)
    except RuntimeError as e:
        # Skip, don't refuse: the frame is kept, noisy (e.g. an older Blender's OIDN refusing
        # a setting it does not know).
        report.once(f"Denoise failed ({e}): the image is not denoised")
        return out
    result = combined.copy()
    result[..., :3] = clean
    out["Combined"] = result
    return out


def render_frame(depsgraph, method: Method, passes=("Combined",), progress=None, stats=None,
                 use_border: bool = True, headlight: Optional[bool] = None, keep: bool = False,
                 settings: Optional[shading.RenderSettings] = None, views: Optional[list] = None,
                 denoised: bool = True, frame_set=None) -> Frame:
    """Exports the depsgraph's view layer and renders the frame (or its border) with
    `method`. headlight: None follows the scene's Lighting setting (and falls back to the
    headlight, said in the report, when nothing in the scene gives light); True/False
    force it. keep: keep the geometry for the next frame. views: a stereo or multi-view
    render's views (export/scene.py View), each rendered with its own camera from the same
    export (Frame.views); None renders the scene camera. The passes Cycles' denoising
    writes ("Noisy Image", "Denoising ...") are made when asked for, and Combined is
    denoised when the scene's Denoise is on (export/settings.py denoising_of) and `denoised`.
    frame_set(frame, subframe): the render engine's, to sample transforms over the shutter
    (motion blur; each view's camera over it); None renders the frame's time alone (said in
    the report when motion blur is on)."""
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
        motion = None
        if frame_set is not None:
            motion = export_motion.sample_motion(depsgraph, frame_set, report,
                                                 [view.camera for view in views] if views else None)
        elif scene.render.use_motion_blur:
            report.once("Motion Blur is not rendered here: this render is of the frame's time alone (F12 and "
                        "animation renders blur)")
        # Cycles' Vector pass, written with motion blur off (with it on, Cycles' is 0 too).
        frame_motion = None
        if "Vector" in passes and not scene.render.use_motion_blur:
            if frame_set is None:
                report.once(f"{depsgraph.view_layer.name}: the Vector pass is 0 here: only F12 and animation "
                            "renders read the previous and next frames")
            else:
                frame_motion = export_motion.sample_frame_motion(depsgraph, frame_set, report,
                                                                 [view.camera for view in views] if views else None)
        origin = export.camera_origin(depsgraph)
        cameras = {view.name: export.export_camera(depsgraph, width, height, origin, view, motion)
                   for view in views} if views else {"": export.export_camera(depsgraph, width, height, origin, motion=motion)}
        export_settings.report_unhonoured(scene, depsgraph.view_layer, report)
        denoising = export_settings.denoising_of(scene, depsgraph.view_layer, report) if denoised else None
        exported = export.export_scene(depsgraph, CACHE, origin, props.radius_factor, threads, report, motion)
    except BaseException:
        CACHE.end_frame(keep=False)
        raise
    t_export = time.perf_counter() - t0
    settings, headlight = lit_settings(scene, exported, settings or export_shading.render_settings_of(scene),
                                       headlight, report)
    summary = (f"Splat Tracer | {exported.instances} instances of {len(CACHE.used)} geometries "
               f"({exported.splats:,} splats, {exported.triangles:,} triangles), {exported.lights} lamps")
    say(summary + " | rendering")
    wanted = tuple(passes)
    # The guides come from the core's passes; a pass only the denoiser needs is not kept.
    guides = [_GUIDES[name] for name in wanted if name in _GUIDES]
    if denoising is not None:
        guides += ["DiffCol"] * denoising.albedo + ["Normal"] * denoising.normal
    if frame_motion is not None:
        guides += ["Position", "Instance"]  # the Vector pass is computed from them (below)
    core_passes = tuple(dict.fromkeys([name for name in wanted if name not in _GUIDES
                                       and name != export_settings.NOISY_IMAGE] + guides))
    t1 = time.perf_counter()
    view_layer = depsgraph.view_layer
    view_passes, completed, counters, t_denoise, denoised_views = {}, True, {}, 0.0, 0
    metadata = {}
    light_groups = export_settings.light_groups(view_layer)
    # Light groups' passes ("Combined_<group>") come with the render, not from `passes`: the
    # denoiser's cut keeps them.
    kept = wanted + tuple(shading.LIGHT_GROUP_PREFIX + g for g in light_groups)
    aovs = []
    for name, kind in export_shading.view_layer_aovs(view_layer).items():
        if name in shading.PASSES or name in cryptomatte.KINDS or name in kept:
            report.once(f"view layer '{view_layer.name}': the Shader AOV '{name}' has the name of a pass "
                        "the engine writes; it is not written")
        else:
            aovs.append((name, kind))
    kept += tuple(name for name, _ in aovs)  # the denoiser's cut keeps them too
    for name, camera in cameras.items():
        moving = exported.render_scene.moving + (camera.motion is not None)
        result = exported.render_scene.render(camera, width, height, settings, method, core_passes,
                                              window=(x0, y0, w, h), threads=threads, progress=progress,
                                              cryptomatte_levels=view_layer.pass_cryptomatte_depth,
                                              light_groups=light_groups,
                                              aovs=aovs, aov_alpha_threshold=view_layer.pass_alpha_threshold,
                                              shutter_curve=motion.curve if motion is not None and moving else None,
                                              rolling_shutter=motion.rolling if motion is not None and moving else None)
        position = result.passes.get("Position")
        if frame_motion is not None:
            if camera.panorama is not None:
                report.once(f"{view_layer.name}: the Vector pass is 0 for a panoramic camera (its motion is "
                            "computed for perspective and orthographic cameras)")
            elif camera.orthographic:
                # Measured with bpy 5.0.1 (tests/blender/test_vector_pass.py).
                report.once(f"{view_layer.name}: the Vector pass of an orthographic camera is its orthographic "
                            "screen motion; Cycles' projects the previous and next frames' positions through the "
                            "lens as if perspective, so the two differ")
            scene_camera = (views[[v.name for v in views].index(name)].camera if views else scene.camera)
            result.passes["Vector"] = export_motion.vector_pass(
                position, result.passes["Instance"], exported.keys, frame_motion, camera,
                scene_camera.name_full, exported.origin, width, height)
        if position is not None:
            # The core's positions are in the local frame; the pass is in world space, as
            # Cycles'. A miss stays 0 (Cycles' value there); a hit is never at the local origin,
            # which is the camera's own position.
            hit = np.any(position != 0.0, axis=-1)
            position[hit] = (position[hit] + exported.origin).astype(np.float32)
        frame_passes = result.passes
        if denoising is not None or set(core_passes) != set(wanted):
            # A stopped render is not denoised, but loses the passes only the denoiser wanted.
            t2 = time.perf_counter()
            frame_passes = denoise_passes(frame_passes, kept, denoising if result.completed else None,
                                          camera.local_from_camera, threads, report)
            t_denoise += time.perf_counter() - t2
            denoised_views += frame_passes.get("Combined") is not result.passes.get("Combined")
        # Every view gets its Cryptomatte layers (cut after the denoiser, which keeps the
        # passes `wanted` names); the manifests, the scene's names, are the same for every
        # view: the result's metadata, written once.
        metadata = cryptomatte_layers(frame_passes, exported.render_scene, view_layer.name)
        view_passes[name] = frame_passes
        completed = completed and result.completed
        counters = counters or result.counters
        if not result.completed:
            break
    t_render = time.perf_counter() - t1
    sampling = sampling_summary(settings, counters, w * h)
    if denoised_views:
        sampling = "; ".join(filter(None, [sampling, f"{denoising.describe()} in {t_denoise:.2f} s"]))
    frame_stats = dict(instances=exported.instances, geometries=len(CACHE.used), built=CACHE.built,
                       reused=CACHE.reused, build_seconds=CACHE.build_seconds, export_seconds=t_export,
                       clouds=exported.clouds, closed_clouds=exported.closed_clouds,
                       render_seconds=t_render, splats=exported.splats, triangles=exported.triangles,
                       lights=exported.lights, headlight=bool(headlight), frame=scene.frame_current,
                       view_layer=view_layer.name, samples=settings.samples, report=list(report.lines),
                       completed=completed, sampling=sampling, views=list(cameras) if views else [],
                       moving=exported.render_scene.moving,
                       camera_moves=any(c.motion is not None for c in cameras.values()),
                       denoise_seconds=t_denoise, **counters)
    CACHE.end_frame(keep)
    HISTORY.append(frame_stats)
    del HISTORY[:-_HISTORY_LIMIT]
    say(f"{summary} | built {CACHE.built}, reused {CACHE.reused} ({CACHE.build_seconds:.2f} s) | "
        f"export {t_export:.2f} s, render {t_render:.2f} s")
    first = next(iter(view_passes.values()))
    return Frame(first, completed, (x0, y0, w, h), width, height, frame_stats, report,
                 view_passes if views else {}, metadata)


def cryptomatte_layers(passes: dict, render_scene, view_layer_name: str) -> dict:
    """Replaces each Cryptomatte pass of `passes` by its RGBA layers (CryptoObject00, ...),
    and returns their metadata for the render result, as Cycles writes it: per kind, the
    view layer's '<layer>.<kind>' name and the manifest of the names the scene holds (Cycles
    lists every object and shader of its scene, whether seen or not)."""
    names = {"CryptoObject": [n for n, _ in render_scene.instance_names],
             "CryptoMaterial": render_scene.material_names,
             "CryptoAsset": [a for _, a in render_scene.instance_names]}
    metadata = {}
    for kind in cryptomatte.KINDS:
        if kind in passes:
            passes.update(cryptomatte.layers(kind, passes.pop(kind)))
            metadata.update(cryptomatte.metadata(f"{view_layer_name}.{kind}", names[kind]))
    return metadata
