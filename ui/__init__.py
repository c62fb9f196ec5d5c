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
        layout.prop(settings, "method")
        layout.prop(settings, "epsilon")
        layout.prop(settings, "radius_factor")
        layout.prop(context.scene.render, "film_transparent")
        if context.scene.world is not None:
            layout.prop(context.scene.world, "color", text="Background")
        layout.operator("splat_tracer.compare", icon="IMAGE_REFERENCE")


class SPLAT_TRACER_PT_visibility(SplatTracerPanel, bpy.types.Panel):
    bl_label = "Visibility"
    bl_context = "render"
    bl_parent_id = "SPLAT_TRACER_PT_render"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        settings = context.scene.splat_tracer
        col = layout.column(heading="Rules")
        col.prop(settings, "use_wrong_hit_elimination")
        col.prop(settings, "use_far_phase")
        col.prop(settings, "use_near_phase")
        sub = col.column()
        sub.active = not settings.use_near_phase
        sub.prop(settings, "use_nearest_centre")
        col = layout.column(heading="Shading")
        col.prop(settings, "use_normal_interpolation")
        sub = col.column()
        sub.active = settings.use_normal_interpolation
        sub.prop(settings, "kernel")


class SPLAT_TRACER_PT_sampling(SplatTracerPanel, bpy.types.Panel):
    bl_label = "Sampling"
    bl_context = "render"
    bl_parent_id = "SPLAT_TRACER_PT_render"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        scene = context.scene
        col = layout.column()
        col.prop(scene.splat_tracer, "samples")
        col.prop(scene.splat_tracer, "shadow_samples")
        # The filter, seed and bounces are Cycles' own settings, read when the add-on is on;
        # shown here because Cycles' panels hide for other engines.
        cycles = getattr(scene, "cycles", None)
        col = layout.column()
        if cycles is not None:
            col.prop(cycles, "pixel_filter_type", text="Pixel Filter")
        col.prop(scene.render, "filter_size", text="Filter Width")
        if cycles is not None:
            col.prop(cycles, "seed")
            col.prop(cycles, "use_animated_seed")


class SPLAT_TRACER_PT_light_paths(SplatTracerPanel, bpy.types.Panel):
    bl_label = "Light Paths"
    bl_context = "render"
    bl_parent_id = "SPLAT_TRACER_PT_render"
    bl_options = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context):
        return super().poll(context) and hasattr(context.scene, "cycles")

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        cycles = context.scene.cycles
        col = layout.column(heading="Max Bounces")
        col.prop(cycles, "max_bounces", text="Total")
        col.prop(cycles, "diffuse_bounces", text="Diffuse")
        col.prop(cycles, "glossy_bounces", text="Glossy")
        col.prop(cycles, "transmission_bounces", text="Transmission")
        col.prop(cycles, "transparent_max_bounces", text="Transparent")


class SPLAT_TRACER_PT_performance(SplatTracerPanel, bpy.types.Panel):
    bl_label = "Performance"
    bl_context = "render"
    bl_parent_id = "SPLAT_TRACER_PT_render"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        render = context.scene.render
        col = layout.column(heading="Threads")
        col.prop(render, "threads_mode", expand=True)
        sub = col.column()
        sub.enabled = render.threads_mode == "FIXED"
        sub.prop(render, "threads")


class SPLAT_TRACER_PT_object(SplatTracerPanel, bpy.types.Panel):
    bl_label = "Splat Cloud"
    bl_context = "object"

    @classmethod
    def poll(cls, context):
        obj = context.object
        return super().poll(context) and obj is not None and obj.type in {"MESH", "POINTCLOUD"}

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        obj = context.object
        layout.prop(obj.splat_tracer, "closed")
        guess = obj.get("splat_tracer_closed_guess")
        if guess:
            layout.label(text=f"Import guess: {guess}", icon="INFO")


class SPLAT_TRACER_PT_passes(SplatTracerPanel, bpy.types.Panel):
    bl_label = "Passes"
    bl_context = "view_layer"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        view_layer = context.view_layer
        layout.prop(view_layer, "use_pass_z", text="Depth")
        layout.prop(view_layer, "use_pass_normal", text="Normal")


classes = (SPLAT_TRACER_PT_render, SPLAT_TRACER_PT_sampling, SPLAT_TRACER_PT_visibility,
           SPLAT_TRACER_PT_light_paths, SPLAT_TRACER_PT_performance,
           SPLAT_TRACER_PT_object, SPLAT_TRACER_PT_passes)

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
