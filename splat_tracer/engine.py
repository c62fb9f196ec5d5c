"""The render engine: Blender's F12 / `blender -b -f` entry point.

Thin on purpose: export the scene and camera, let the core render, write the passes.
"""
from __future__ import annotations

import math
import time
import traceback
from dataclasses import dataclass

import bpy
import numpy as np

from . import core, export

BACKGROUND_DEPTH = 1e10  # what Cycles writes in Z where nothing is hit


def image_size(render) -> tuple[int, int]:
    """Output size in pixels after the resolution percentage, as Blender computes it."""
    scale = render.resolution_percentage / 100.0
    return max(1, int(render.resolution_x * scale)), max(1, int(render.resolution_y * scale))


def border_window(render, width: int, height: int) -> tuple[int, int, int, int]:
    """(x0, y0 from the top, w, h) of the rendered region: the border when one is set."""
    if not render.use_border:
        return 0, 0, width, height
    # Blender rounds the border edges to the nearest pixel (round_fl_to_int).
    x0, x1 = (math.floor(v * width + 0.5) for v in (render.border_min_x, render.border_max_x))
    yb0, yb1 = (math.floor(v * height + 0.5) for v in (render.border_min_y, render.border_max_y))
    x1, yb1 = max(x1, x0 + 1), max(yb1, yb0 + 1)
    return x0, height - yb1, x1 - x0, yb1 - yb0


def background_rgba(scene) -> tuple:
    if scene.render.film_transparent:
        return (0.0, 0.0, 0.0, 0.0)
    colour = scene.world.color if scene.world is not None else (0.0, 0.0, 0.0)
    return (colour[0], colour[1], colour[2], 1.0)


def _set_pass(layer, name: str, pixels: np.ndarray) -> None:
    """Writes (h, w, c) top-row-first pixels into a pass (whose rows run bottom to top)."""
    layer.passes[name].rect.foreach_set(np.ascontiguousarray(pixels[::-1], dtype=np.float32).ravel())


class SplatTracerEngine(bpy.types.RenderEngine):
    bl_idname = "SPLAT_TRACER"
    bl_label = "Splat Tracer"
    bl_use_preview = False
    bl_use_postprocess = True

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)

    def update_render_passes(self, scene=None, renderlayer=None):
        self.register_pass(scene, renderlayer, "Combined", 4, "RGBA", "COLOR")
        if renderlayer.use_pass_z:
            self.register_pass(scene, renderlayer, "Depth", 1, "Z", "VALUE")
        if renderlayer.use_pass_normal:
            self.register_pass(scene, renderlayer, "Normal", 3, "XYZ", "VECTOR")

    def render(self, depsgraph):
        # Blender does not fail bpy.ops.render.render() for an exception raised here: it
        # must be reported, or a batch render would silently write an empty image.
        try:
            self._render(depsgraph)
        except Exception as e:  # noqa: BLE001 - everything is reported to the user
            traceback.print_exc()
            message = f"Splat Tracer: {e}"
            self.report({"ERROR"}, message)
            self.error_set(message)

    def _render(self, depsgraph):
        scene = depsgraph.scene
        layer_settings = depsgraph.view_layer
        want_depth, want_normal = layer_settings.use_pass_z, layer_settings.use_pass_normal

        def progress(done: int, total: int) -> bool:
            self.update_progress(done / max(total, 1))
            return self.test_break()

        frame = render_frame(depsgraph, scene.splat_tracer.core_method(), depth=want_depth, normal=want_normal,
                             progress=progress, report=self.report, stats=lambda s: self.update_stats("", s))
        x0, y0, w, h = frame.window
        result = self.begin_result(0, 0, w, h)
        layer = result.layers[0]
        _set_pass(layer, "Combined", frame.image.rgba)
        if want_depth:
            _set_pass(layer, "Depth", frame.image.depth)
        if want_normal:
            _set_pass(layer, "Normal", frame.image.normal)
        self.end_result(result, cancel=not frame.image.completed)


@dataclass
class Frame:
    image: core.RenderResult
    window: tuple  # (x0, y0 from the top, w, h) within the width x height frame
    width: int
    height: int


def render_frame(depsgraph, method: core.Method, depth=True, normal=True, progress=None, report=None,
                 stats=None, use_border=True) -> Frame:
    """Exports the visible clouds and the camera and renders the frame (or its border) with
    `method`: what F12 does, and what the A/B compare operator does twice."""
    scene = depsgraph.scene
    width, height = image_size(scene.render)
    x0, y0, w, h = border_window(scene.render, width, height) if use_border else (0, 0, width, height)
    threads = scene.render.threads
    say = stats or (lambda s: None)

    t0 = time.perf_counter()
    say("Splat Tracer | exporting splats")
    exported = export.export_scene(depsgraph, scene.splat_tracer.radius_factor, threads)
    for name in exported.skipped:
        if report:
            report({"WARNING"}, f"Splat Tracer: point cloud '{name}' has no splat normals; not rendered")
    camera = export.export_camera(depsgraph, width, height, exported.origin)
    t_export = time.perf_counter() - t0
    summary = f"Splat Tracer | {len(exported.scene):,} splats in {exported.objects} clouds"
    say(summary + " | rendering")
    image = exported.scene.render(camera, width, height, window=(x0, y0, w, h), background=background_rgba(scene),
                                  depth=depth, normal=normal, threads=threads, progress=progress, method=method)
    say(f"{summary} | export {t_export:.2f} s, total {time.perf_counter() - t0:.2f} s")
    return Frame(image, (x0, y0, w, h), width, height)


classes = (SplatTracerEngine,)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
