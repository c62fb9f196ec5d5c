"""Panels, shown only when Splat Tracer is the render engine."""
import bpy

ENGINE = "SPLAT_TRACER"


class SplatTracerPanel:
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    COMPAT_ENGINES = {ENGINE}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES


class SPLAT_TRACER_PT_render(SplatTracerPanel, bpy.types.Panel):
    bl_label = "Splat Tracer"
    bl_context = "render"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        settings = context.scene.splat_tracer
        layout.prop(settings, "radius_factor")
        render = context.scene.render
        col = layout.column(heading="Threads")
        col.prop(render, "threads_mode", expand=True)
        sub = col.column()
        sub.enabled = render.threads_mode == "FIXED"
        sub.prop(render, "threads")
        layout.prop(render, "film_transparent")
        if context.scene.world is not None:
            layout.prop(context.scene.world, "color", text="Background")


class SPLAT_TRACER_PT_passes(SplatTracerPanel, bpy.types.Panel):
    bl_label = "Passes"
    bl_context = "view_layer"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        view_layer = context.view_layer
        layout.prop(view_layer, "use_pass_z", text="Depth")
        layout.prop(view_layer, "use_pass_normal", text="Normal")


classes = (SPLAT_TRACER_PT_render, SPLAT_TRACER_PT_passes)

# Blender's engine-agnostic panels (output format, camera, object, ...) list the engines they
# show for; the ones that show for the built-in BLENDER_RENDER also make sense here.
_extended_panels = []


def _extend_builtin_panels():
    for panel in bpy.types.Panel.__subclasses__():
        engines = getattr(panel, "COMPAT_ENGINES", None)
        if isinstance(engines, set) and "BLENDER_RENDER" in engines and ENGINE not in engines:
            engines.add(ENGINE)
            _extended_panels.append(panel)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    _extend_builtin_panels()


def unregister():
    for panel in _extended_panels:
        panel.COMPAT_ENGINES.discard(ENGINE)
    _extended_panels.clear()
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
