"""The render engine: Blender's F12 / `blender -b -f` entry point.

Thin on purpose: export the scene and camera, let the core render, write the passes.
"""
from __future__ import annotations

import math
import time
import traceback

import bpy
import numpy as np

from . import export

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
        settings = scene.splat_tracer
        width, height = image_size(scene.render)
        x0, y0, w, h = border_window(scene.render, width, height)
        threads = scene.render.threads

        t0 = time.perf_counter()
        self.update_stats("", "Splat Tracer | exporting splats")
        exported = export.export_scene(depsgraph, settings.radius_factor, threads)
        for name in exported.skipped:
            self.report({"WARNING"}, f"Splat Tracer: point cloud '{name}' has no splat normals; not rendered")
        camera = export.export_camera(depsgraph, width, height, exported.origin)
        t_export = time.perf_counter() - t0

        layer_settings = depsgraph.view_layer
        want_depth, want_normal = layer_settings.use_pass_z, layer_settings.use_pass_normal
        stats = f"Splat Tracer | {len(exported.scene):,} splats in {exported.objects} clouds"
        self.update_stats("", stats + " | rendering")

        def progress(done: int, total: int) -> bool:
            self.update_progress(done / max(total, 1))
            return self.test_break()

        image = exported.scene.render(camera, width, height, window=(x0, y0, w, h),
                                      background=background_rgba(scene), depth=want_depth,
                                      normal=want_normal, threads=threads, progress=progress)
        result = self.begin_result(0, 0, w, h)
        layer = result.layers[0]
        _set_pass(layer, "Combined", image.rgba)
        if want_depth:
            _set_pass(layer, "Depth", image.depth)
        if want_normal:
            _set_pass(layer, "Normal", image.normal)
        self.end_result(result, cancel=not image.completed)
        total = time.perf_counter() - t0
        self.update_stats("", f"{stats} | export {t_export:.2f} s, total {total:.2f} s")


classes = (SplatTracerEngine,)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
