"""The render engine: Blender's F12 / `blender -b -f` / `-a` entry point.

Thin on purpose: the session (session.py) exports and renders; this file registers the
passes, writes them into the view layer's result and tells the user what happened.
Blender calls render() once per view layer, each with its own depsgraph.
"""
from __future__ import annotations

import traceback

import bpy
import numpy as np

from ..render import ab, cryptomatte, shading
from . import denoise, session, viewport
from .export import settings as export_settings
from .export.scene import View

# Blender 5.0 renamed five passes (Cycles and EEVEE write "Diffuse Color", "Emission",
# "Object Index", "Material Index" and "Environment" there, "DiffCol", "Emit", "IndexOB",
# "IndexMA" and "Env" before). A pass must carry the name
# Blender's own engines give it, or the compositor's Render Layers node shows it as a
# different socket and links made for Cycles (an ID Mask on Object Index) are lost.
_NEW_PASS_NAMES = bpy.app.version >= (5, 0, 0)
# Cycles' denoising passes (export/settings.py names them and says when each is written):
# Blender's name -> (channels, channel ids, type), as Cycles' add-on registers them.
_DENOISING_PASSES = {export_settings.NOISY_IMAGE: (4, "RGBA", "COLOR"),
                     export_settings.DENOISING_NORMAL: (3, "XYZ", "VECTOR"),
                     export_settings.DENOISING_ALBEDO: (3, "RGB", "COLOR"),
                     export_settings.DENOISING_DEPTH: (1, "Z", "VALUE")}
# Blender's passes this engine writes: (view-layer switch -- dotted for an add-on's
# property group -- the core's pass name, Blender's pass name, channels, channel ids, type).
_PASSES = (
    ("use_pass_z", "Depth", "Depth", 1, "Z", "VALUE"),
    ("use_pass_normal", "Normal", "Normal", 3, "XYZ", "VECTOR"),
    ("use_pass_diffuse_color", "DiffCol", "Diffuse Color" if _NEW_PASS_NAMES else "DiffCol", 3, "RGB", "COLOR"),
    ("use_pass_emit", "Emit", "Emission" if _NEW_PASS_NAMES else "Emit", 3, "RGB", "COLOR"),
    ("use_pass_shadow", "Shadow", "Shadow", 3, "RGB", "COLOR"),
    ("use_pass_object_index", "IndexOB", "Object Index" if _NEW_PASS_NAMES else "IndexOB", 1, "X", "VALUE"),
    ("use_pass_material_index", "IndexMA", "Material Index" if _NEW_PASS_NAMES else "IndexMA", 1, "X", "VALUE"),
    ("use_pass_position", "Position", "Position", 3, "XYZ", "VECTOR"),
    ("use_pass_mist", "Mist", "Mist", 1, "Z", "VALUE"),
    ("use_pass_environment", "Env", "Environment" if _NEW_PASS_NAMES else "Env", 3, "RGB", "COLOR"),
    # Cycles' light passes (Blender 5.0 spells them out too).
    ("use_pass_diffuse_direct", "DiffDir", "Diffuse Direct" if _NEW_PASS_NAMES else "DiffDir", 3, "RGB", "COLOR"),
    ("use_pass_diffuse_indirect", "DiffInd", "Diffuse Indirect" if _NEW_PASS_NAMES else "DiffInd", 3, "RGB", "COLOR"),
    ("use_pass_glossy_direct", "GlossDir", "Glossy Direct" if _NEW_PASS_NAMES else "GlossDir", 3, "RGB", "COLOR"),
    ("use_pass_glossy_indirect", "GlossInd", "Glossy Indirect" if _NEW_PASS_NAMES else "GlossInd", 3, "RGB", "COLOR"),
    ("use_pass_glossy_color", "GlossCol", "Glossy Color" if _NEW_PASS_NAMES else "GlossCol", 3, "RGB", "COLOR"),
    ("use_pass_transmission_direct", "TransDir", "Transmission Direct" if _NEW_PASS_NAMES else "TransDir", 3, "RGB",
     "COLOR"),
    ("use_pass_transmission_indirect", "TransInd", "Transmission Indirect" if _NEW_PASS_NAMES else "TransInd", 3,
     "RGB", "COLOR"),
    ("use_pass_transmission_color", "TransCol", "Transmission Color" if _NEW_PASS_NAMES else "TransCol", 3, "RGB",
     "COLOR"),
    ("use_pass_ambient_occlusion", "AO", "Ambient Occlusion" if _NEW_PASS_NAMES else "AO", 3, "RGB", "COLOR"),
    # Cycles' motion to the previous and next frames with motion blur off (export/motion.py
    # vector_pass); 0 with it on, as Cycles'.
    ("use_pass_vector", "Vector", "Vector", 4, "XYZW", "VECTOR"),
    # The mesh's UV map at the first hit (0 on clouds, said in the report).
    ("use_pass_uv", "UV", "UV", 3, "UVA", "VECTOR"),
    # Cycles' own switch (view_layer.cycles, the Cycles add-on's), name and channels.
    ("cycles.use_pass_shadow_catcher", "Shadow Catcher", "Shadow Catcher", 3, "RGB", "COLOR"),
)
SPLAT_COUNT = "Splat Count"  # debug pass: the splats that formed each surface point
# Cryptomatte: the view layer's switch of each kind (render/cryptomatte.py KINDS), whose
# passes are <kind>00, <kind>01, ... (4 channels, two (id, coverage) pairs each), as Cycles names them.
_CRYPTOMATTE = dict(zip(cryptomatte.KINDS, ("use_pass_cryptomatte_object", "use_pass_cryptomatte_material",
                                            "use_pass_cryptomatte_asset")))
_BLENDER_NAME = {core_name: blender_name for _, core_name, blender_name, *_ in _PASSES}


def _switch(view_layer, prop: str) -> bool:
    """A pass's switch on the view layer ('cycles.use_pass_...': off when the Cycles add-on,
    which owns it, is not enabled)."""
    owner, _, name = prop.rpartition(".")
    group = getattr(view_layer, owner, None) if owner else view_layer
    return bool(getattr(group, name, False))


def wanted_passes(view_layer, scene=None) -> tuple:
    """The core's names of the passes the view layer asks for (with the scene: and Cycles'
    denoising passes, by Cycles' names)."""
    names = [name for prop, name, *_ in _PASSES if _switch(view_layer, prop)]
    names += [kind for kind, prop in _CRYPTOMATTE.items() if _switch(view_layer, prop)]
    if view_layer.splat_tracer.use_pass_splat_count:
        names.append(SPLAT_COUNT)
    if scene is not None:
        names += export_settings.denoising_passes(scene, view_layer)
    return tuple(names)


def _set_pass(layer, view: str, name: str, pixels: np.ndarray) -> None:
    """Writes (h, w[, c]) top-row-first pixels into the pass the core calls `name` (whose
    rows run bottom to top), in the result's view `view` (a stereo or multi-view render has
    one pass per view)."""
    flat = np.ascontiguousarray(pixels[::-1], dtype=np.float32).ravel()
    layer.passes.find_by_name(_BLENDER_NAME.get(name, name), view).rect.foreach_set(flat)


class SplatTracerEngine(bpy.types.RenderEngine):
    bl_idname = "SPLAT_TRACER"
    bl_label = "Splat Tracer"
    bl_use_preview = False
    bl_use_postprocess = True

    def update_render_passes(self, scene=None, renderlayer=None):
        self.register_pass(scene, renderlayer, "Combined", 4, "RGBA", "COLOR")
        for prop, _, name, channels, ids, kind in _PASSES:
            if _switch(renderlayer, prop):
                self.register_pass(scene, renderlayer, name, channels, ids, kind)
        for name in export_settings.light_groups(renderlayer):  # Cycles' "Combined_<group>"
            self.register_pass(scene, renderlayer, shading.LIGHT_GROUP_PREFIX + name, 3, "RGB", "COLOR")
        if renderlayer.splat_tracer.use_pass_splat_count:
            self.register_pass(scene, renderlayer, SPLAT_COUNT, 1, "X", "VALUE")
        # Shader AOVs, as Cycles registers them: RGBA for a colour AOV, X for a value one.
        for aov in renderlayer.aovs:
            if aov.is_valid:
                if aov.type == "COLOR":
                    self.register_pass(scene, renderlayer, aov.name, 4, "RGBA", "COLOR")
                else:
                    self.register_pass(scene, renderlayer, aov.name, 1, "X", "VALUE")
        for name in export_settings.denoising_passes(scene, renderlayer):
            self.register_pass(scene, renderlayer, name, *_DENOISING_PASSES[name])
        layers = cryptomatte.slots_of(renderlayer.pass_cryptomatte_depth) // 2
        for kind, prop in _CRYPTOMATTE.items():
            if _switch(renderlayer, prop):
                for i in range(layers):
                    # Lower-case channel ids, as Cycles registers them (the EXR's '.r', '.g', ...).
                    self.register_pass(scene, renderlayer, f"{kind}{i:02d}", 4, "rgba", "COLOR")

    def _views(self, scene) -> list:
        """A stereo or multi-view render's views, each with its camera as Blender gives it
        for that view (export/scene.py View); [] for a render of the scene camera alone."""
        if not scene.render.use_multiview:
            return []
        views = []
        for name in export_settings.stereo_views(scene.render):
            self.active_view_set(name)
            camera = self.camera_override or scene.camera
            if camera is None:
                continue
            # use_spherical_stereo=False: the eye's camera moved (and for Toe-in turned) as a
            # whole, also for a panorama (export/settings.py says it for one).
            views.append(View(name, camera, self.camera_model_matrix(camera, use_spherical_stereo=False),
                              self.camera_shift_x(camera, use_spherical_stereo=False)))
        return views

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
        view_layer = depsgraph.view_layer

        def progress(done: int, total: int) -> bool:
            self.update_progress(done / max(total, 1))
            return self.test_break()

        keep = scene.render.use_persistent_data or self.is_animation
        frame = session.render_frame(depsgraph, scene.splat_tracer.core_method(), ("Combined",) + wanted_passes(
            view_layer, scene), progress=progress, stats=lambda s: self.update_stats("", s), keep=keep,
            frame_set=self.frame_set, views=self._views(scene))
        for line in frame.report.lines:
            self.report({"WARNING"}, f"Splat Tracer: {line}")
        x0, y0, w, h = frame.window
        # Each view layer's render goes into its own layer of the result.
        result = self.begin_result(0, 0, w, h, layer=view_layer.name)
        layer = result.layers[0]
        for view in result.views:
            # Each view its own render. A view the render did not reach (stopped in an earlier
            # one) is left unwritten -- black, as Cycles leaves the views after a cancelled one --
            # never given another view's image.
            passes = frame.views.get(view.name) if frame.views else frame.passes
            for name, pixels in (passes or {}).items():
                _set_pass(layer, view.name, name, pixels)
        if frame.metadata:
            # Cryptomatte's manifests, saved in the EXR's header: on the engine's whole result
            # (get_result), as Cycles writes them -- a tile's begin_result() result is merged
            # into it without its metadata.
            whole = self.get_result()
            for key, value in frame.metadata.items():
                whole.stamp_data_add_field(key, value)
        if frame.completed:
            self.end_result(result)
        else:
            # Stopped (Esc): the frame is incomplete and must not be saved as if finished. The
            # error is set before the result is ended: Blender then writes no file. (Ending
            # without the error made Blender's EXR writers crash on the result -- found by the
            # hostile test; tests/blender/test_import_and_render.py reproduces it.) What was
            # rendered stays shown, as Cycles leaves a cancelled render: the views done, the
            # stopped one's samples so far, and black in the views never reached.
            missing = [view.name for view in result.views if frame.views and view.name not in frame.views]
            message = (f"Splat Tracer: render stopped before the end; the image of view layer '{view_layer.name}' "
                       "is incomplete and was not saved"
                       + (f" (not rendered: view {', '.join(repr(v) for v in missing)})" if missing else ""))
            self.report({"ERROR"}, message)
            self.error_set(message)
            self.end_result(result, cancel=True, do_merge_results=True)
            return
        s = frame.stats
        self.report({"INFO"}, f"Splat Tracer: {s['instances']} instances, built {s['built']} and reused "
                              f"{s['reused']} geometries ({s['build_seconds']:.2f} s), rendered in "
                              f"{s['render_seconds']:.2f} s" + (f"; {s['sampling']}" if s["sampling"] else ""))

    # -- the viewport's Rendered mode ---------------------------------------------------
    # view_update / view_draw run on Blender's main thread; the session renders on its own
    # thread (viewport.py) and never calls bpy. Only _draw_pixels needs a GPU context.

    def _viewport_session(self) -> viewport.ViewportSession:
        vs = getattr(self, "_splat_viewport", None)
        if vs is None:
            vs = self._splat_viewport = viewport.ViewportSession()
            vs.start()
        return vs

    def view_update(self, context, depsgraph):
        vs = self._viewport_session()
        try:
            viewport.update_from_depsgraph(vs, depsgraph, first=vs.exported is None)
        except Exception as e:  # noqa: BLE001 - shown in the viewport, never raised into the draw loop
            traceback.print_exc()
            vs.error = str(e)
            self.update_stats("", f"Splat Tracer: {e}")

    def view_draw(self, context, depsgraph):
        width, height = context.region.width, context.region.height
        if width <= 0 or height <= 0:
            # A region collapsed to nothing (a dragged split, a minimised area) has no pixels and
            # its view matrices are NaN: nothing to draw or render. The session keeps what it
            # has; the first draw at a real size sets that view and rendering resumes.
            return
        vs = self._viewport_session()
        scene = depsgraph.scene
        vs.set_view(viewport.view_of(scene, depsgraph, context.region, context.region_data, context.space_data))
        images, version = vs.snapshot()
        props = scene.splat_tracer.ab
        mode = props.mode if "A" in images or "B" in images else "OFF"
        if images:
            view = scene.view_settings
            pixels = ab.display_buffer(mode, (height, width, 4), scene=_pixels(images.get("SCENE")),
                                       a=_pixels(images.get("A")), b=_pixels(images.get("B")), split=props.split,
                                       overlay=props.show_difference and mode != "OFF", exposure=view.exposure,
                                       gamma=view.gamma)
            _draw_pixels(self, scene, pixels, width, height)
            self.update_stats("", viewport.status(images, vs.done))
        if vs.error:
            self.update_stats("", f"Splat Tracer: {vs.error}")
        elif not vs.done or version != getattr(self, "_splat_drawn", None):
            self.tag_redraw()  # samples keep arriving (or the newest pass is not drawn yet): draw again
        self._splat_drawn = version if vs.done else None

    def __del__(self):
        vs = getattr(self, "_splat_viewport", None)
        if vs is not None:
            vs.close()


def _pixels(image):
    return None if image is None else image.pixels


def _draw_pixels(engine, scene, pixels: np.ndarray, width: int, height: int) -> None:
    """Draws a (h, w, 4) premultiplied scene-linear buffer (top row first) over the region,
    through the scene's display transform. The only code that needs a GPU: not run headless."""
    import gpu
    from gpu_extras.presets import draw_texture_2d

    h, w = pixels.shape[:2]
    data = gpu.types.Buffer("FLOAT", w * h * 4, np.ascontiguousarray(pixels[::-1], np.float32).ravel())
    texture = gpu.types.GPUTexture((w, h), format="RGBA16F", data=data)
    gpu.state.blend_set("ALPHA_PREMULT")
    engine.bind_display_space_shader(scene)
    draw_texture_2d(texture, (0, 0), width, height)
    engine.unbind_display_space_shader()
    gpu.state.blend_set("NONE")


classes = (SplatTracerEngine,)


@bpy.app.handlers.persistent  # kept when another file is loaded
def _job_ended(scene, *_):
    session.release_after_job(scene)


_JOB_END_HANDLERS = (bpy.app.handlers.render_complete, bpy.app.handlers.render_cancel)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    for handlers in _JOB_END_HANDLERS:
        if _job_ended not in handlers:
            handlers.append(_job_ended)


def unregister():
    for handlers in _JOB_END_HANDLERS:
        if _job_ended in handlers:
            handlers.remove(_job_ended)
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
    # The denoiser's kept OIDN device goes with the add-on (a reload makes a new module).
    denoise.release()
