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
        layout.prop(settings, "lighting")
        layout.prop(settings, "method")
        layout.prop(settings, "epsilon")
        layout.prop(settings, "radius_factor")
        layout.prop(context.scene.render, "film_transparent")
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
        sub.prop(settings, "crease_angle")


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
        col.prop(scene.splat_tracer, "sky_light")
        sub = col.column()
        sub.active = scene.splat_tracer.sky_light == "AO"
        sub.prop(scene.splat_tracer, "ao_samples")
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
        layout.operator("splat_tracer.estimate_normals", icon="NORMALS_VERTEX")


class SPLAT_TRACER_PT_passes(SplatTracerPanel, bpy.types.Panel):
    bl_label = "Passes"
    bl_context = "view_layer"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        view_layer = context.view_layer
        col = layout.column(heading="Data")
        col.prop(view_layer, "use_pass_z", text="Depth")
        col.prop(view_layer, "use_pass_normal", text="Normal")
        col.prop(view_layer, "use_pass_object_index", text="Object Index")
        col = layout.column(heading="Light")
        col.prop(view_layer, "use_pass_diffuse_color", text="Diffuse Color")
        col.prop(view_layer, "use_pass_emit", text="Emission")
        col.prop(view_layer, "use_pass_shadow", text="Shadow")
        col = layout.column(heading="Debug")
        col.prop(view_layer.splat_tracer, "use_pass_splat_count")


class SPLAT_TRACER_PT_object_visibility(SplatTracerPanel, bpy.types.Panel):
    """Ray visibility and holdout, as Cycles reads them (its own panel hides for other engines)."""
    bl_label = "Ray Visibility"
    bl_context = "object"

    @classmethod
    def poll(cls, context):
        obj = context.object
        return super().poll(context) and obj is not None and obj.type not in {"CAMERA", "LIGHT", "EMPTY"}

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        obj = context.object
        col = layout.column(heading="Ray Visibility")
        for prop, text in (("visible_camera", "Camera"), ("visible_diffuse", "Diffuse"), ("visible_glossy", "Glossy"),
                           ("visible_transmission", "Transmission"), ("visible_shadow", "Shadow")):
            col.prop(obj, prop, text=text)
        layout.prop(obj, "is_holdout")
        layout.prop(obj, "pass_index")


class SPLAT_TRACER_PT_light(SplatTracerPanel, bpy.types.Panel):
    """The lamp settings the engine reads (Cycles' light panel hides for other engines)."""
    bl_label = "Light"
    bl_context = "data"

    @classmethod
    def poll(cls, context):
        return super().poll(context) and context.light is not None

    def draw(self, context):
        layout = self.layout
        light = context.light
        layout.row().prop(light, "type", expand=True)
        layout.use_property_split = True
        col = layout.column()
        col.prop(light, "color")
        col.prop(light, "energy", text="Strength" if light.type == "SUN" else "Power")
        if light.type in {"POINT", "SPOT"}:
            col.prop(light, "shadow_soft_size", text="Radius")
            col.prop(light, "use_soft_falloff")
        elif light.type == "SUN":
            col.prop(light, "angle")
        elif light.type == "AREA":
            col.prop(light, "shape")
            if light.shape in {"SQUARE", "DISK"}:
                col.prop(light, "size")
            else:
                col.prop(light, "size", text="Size X")
                col.prop(light, "size_y", text="Y")
        if light.type == "SPOT":
            col.prop(light, "spot_size", text="Spot Size")
            col.prop(light, "spot_blend", text="Blend")
        col.prop(light, "use_shadow", text="Cast Shadow")


def _draw_surface(layout, idblock, output_type: str, input_name: str) -> None:
    """The node set-up the engine reads, drawn as Cycles' Surface panels draw it."""
    tree = idblock.node_tree
    output = next((n for n in tree.nodes if n.type == output_type and n.is_active_output), None) if tree else None
    if output is None:
        layout.label(text="No output node")
        return
    layout.template_node_view(tree, output, output.inputs[input_name])


class SPLAT_TRACER_PT_material(SplatTracerPanel, bpy.types.Panel):
    bl_label = "Surface"
    bl_context = "material"

    @classmethod
    def poll(cls, context):
        return super().poll(context) and context.material is not None

    def draw(self, context):
        _draw_surface(self.layout, context.material, "OUTPUT_MATERIAL", "Surface")


class SPLAT_TRACER_PT_world(SplatTracerPanel, bpy.types.Panel):
    bl_label = "Surface"
    bl_context = "world"

    @classmethod
    def poll(cls, context):
        return super().poll(context) and context.world is not None

    def draw(self, context):
        _draw_surface(self.layout, context.world, "OUTPUT_WORLD", "Surface")


classes = (SPLAT_TRACER_PT_render, SPLAT_TRACER_PT_sampling, SPLAT_TRACER_PT_visibility,
           SPLAT_TRACER_PT_light_paths, SPLAT_TRACER_PT_performance,
           SPLAT_TRACER_PT_object, SPLAT_TRACER_PT_object_visibility, SPLAT_TRACER_PT_passes,
           SPLAT_TRACER_PT_light, SPLAT_TRACER_PT_material, SPLAT_TRACER_PT_world)

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
