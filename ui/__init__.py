"""Panels, shown only when Splat Tracer is the render engine."""
import fnmatch

import bpy

ENGINE = "SPLAT_TRACER"


class SplatTracerPanel:
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    COMPAT_ENGINES = {ENGINE}
    # The context member the panel draws ("object", "world", ...): without one (no world in
    # the scene, no material in the slot) the panel is hidden, as Cycles' panels are.
    context_member = None

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES and (
            cls.context_member is None or getattr(context, cls.context_member, None) is not None)


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
        # Samples, noise threshold, time limit, filter and seed are Cycles' own settings (the one
        # place they are kept), drawn here because Cycles' panels hide for other engines.
        cycles = getattr(scene, "cycles", None)
        if cycles is None:
            layout.label(text="Cycles add-on off: its sampling settings cannot be read", icon="INFO")
            layout.prop(scene.splat_tracer, "samples")
        else:
            for heading, prefix, samples in (("Viewport", "preview_", "preview_samples"), ("Render", "", "samples")):
                col = layout.column(heading=heading)
                row = col.row(heading="Noise Threshold")
                row.prop(cycles, f"use_{prefix}adaptive_sampling", text="")
                sub = row.row()
                sub.active = getattr(cycles, f"use_{prefix}adaptive_sampling")
                sub.prop(cycles, f"{prefix}adaptive_threshold", text="")
                col.prop(cycles, samples, text="Max Samples" if sub.active else "Samples")
                sub = col.column()
                sub.active = getattr(cycles, f"use_{prefix}adaptive_sampling")
                sub.prop(cycles, f"{prefix}adaptive_min_samples", text="Min Samples")
                if not prefix:
                    col.prop(cycles, "time_limit")
                # Cycles' Denoise, applied with OpenImageDenoise (blender/denoise.py; the
                # viewport's to its last pass). Not `denoiser`/`preview_denoiser`: drawing
                # those enums computes their items, which enumerates GPU devices (a CUDA
                # warning in every session).
                col.prop(cycles, f"use_{prefix}denoising", text="Denoise")
                sub = col.column()
                sub.active = getattr(cycles, f"use_{prefix}denoising")
                sub.prop(cycles, f"{prefix}denoising_input_passes", text="Passes")
                sub.prop(cycles, f"{prefix}denoising_prefilter", text="Prefilter")
                sub.prop(cycles, f"{prefix}denoising_quality", text="Quality")
        col = layout.column()
        col.prop(scene.splat_tracer, "shadow_samples")
        col.prop(scene.splat_tracer, "sky_light")
        sub = col.column()
        sub.active = scene.splat_tracer.sky_light == "AO"
        sub.prop(scene.splat_tracer, "ao_samples")
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
        col = layout.column(heading="Clamping")
        col.prop(cycles, "sample_clamp_direct", text="Direct Light")
        col.prop(cycles, "sample_clamp_indirect", text="Indirect Light")
        col = layout.column(heading="Caustics")
        col.prop(cycles, "blur_glossy", text="Filter Glossy")


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
    context_member = "object"

    @classmethod
    def poll(cls, context):
        obj = context.object
        return super().poll(context) and obj.type in {"MESH", "POINTCLOUD"}

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
        if hasattr(view_layer, "cycles"):
            col.prop(view_layer.cycles, "use_pass_shadow_catcher", text="Shadow Catcher")
        # (The Properties editor's context has no world outside the World tab: the scene's.)
        scene = getattr(context, "scene", None)
        _draw_light_passes(layout, view_layer, scene.world if scene is not None else getattr(context, "world", None))
        col = layout.column(heading="Debug")
        col.prop(view_layer.splat_tracer, "use_pass_splat_count")


def _draw_light_passes(layout, view_layer, world):
    """Cycles' light passes, laid out as Cycles' Light panel: a row of Direct, Indirect and
    Color per lobe, then AO (with the world's AO distance, which Cycles shows under Fast GI,
    a panel the engine does not open) and Vector."""
    col = layout.column(align=True)
    for lobe, label in (("diffuse", "Diffuse"), ("glossy", "Glossy"), ("transmission", "Transmission")):
        row = col.row(heading=label, align=True)
        row.prop(view_layer, f"use_pass_{lobe}_direct", text="Direct", toggle=True)
        row.prop(view_layer, f"use_pass_{lobe}_indirect", text="Indirect", toggle=True)
        row.prop(view_layer, f"use_pass_{lobe}_color", text="Color", toggle=True)
    col = layout.column(heading="Other")
    col.prop(view_layer, "use_pass_ambient_occlusion", text="Ambient Occlusion")
    if world is not None:
        sub = col.column()
        sub.active = view_layer.use_pass_ambient_occlusion
        sub.prop(world.light_settings, "distance", text="AO Distance")
    col.prop(view_layer, "use_pass_vector", text="Vector")


class SPLAT_TRACER_PT_passes_light_groups(SplatTracerPanel, bpy.types.Panel):
    """The view layer's light groups (Blender's own list and operators, as Cycles' panel):
    each gets a Combined_<group> pass."""
    bl_label = "Light Groups"
    bl_context = "view_layer"
    bl_parent_id = "SPLAT_TRACER_PT_passes"

    def draw(self, context):
        view_layer = context.view_layer
        row = self.layout.row()
        row.template_list("UI_UL_list", "lightgroups", view_layer, "lightgroups", view_layer,
                          "active_lightgroup_index", rows=2)
        col = row.column(align=True)
        col.operator("scene.view_layer_add_lightgroup", icon="ADD", text="")
        col.operator("scene.view_layer_remove_lightgroup", icon="REMOVE", text="")


def _draw_light_group(layout, owner, view_layer):
    layout.use_property_split = True
    layout.prop_search(owner, "lightgroup", view_layer, "lightgroups", text="Light Group")


class SPLAT_TRACER_PT_object_light_group(SplatTracerPanel, bpy.types.Panel):
    """The light group of an object's emission or of a lamp (Cycles' Object > Shading)."""
    bl_label = "Light Group"
    bl_context = "object"
    context_member = "object"

    @classmethod
    def poll(cls, context):
        return super().poll(context) and hasattr(context.object, "lightgroup")

    def draw(self, context):
        _draw_light_group(self.layout, context.object, context.view_layer)


class SPLAT_TRACER_PT_world_light_group(SplatTracerPanel, bpy.types.Panel):
    bl_label = "Light Group"
    bl_context = "world"
    context_member = "world"

    def draw(self, context):
        _draw_light_group(self.layout, context.world, context.view_layer)


class SPLAT_TRACER_PT_passes_cryptomatte(SplatTracerPanel, bpy.types.Panel):
    """Blender's Cryptomatte settings of the view layer, as Cycles' panel shows them (Accurate
    Mode left out, as there: neither Cycles nor the engine reads it)."""
    bl_label = "Cryptomatte"
    bl_context = "view_layer"
    bl_parent_id = "SPLAT_TRACER_PT_passes"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        view_layer = context.view_layer
        col = layout.column()
        col.prop(view_layer, "use_pass_cryptomatte_object", text="Object")
        col.prop(view_layer, "use_pass_cryptomatte_material", text="Material")
        col.prop(view_layer, "use_pass_cryptomatte_asset", text="Asset")
        col = layout.column()
        col.active = any((view_layer.use_pass_cryptomatte_object, view_layer.use_pass_cryptomatte_material,
                          view_layer.use_pass_cryptomatte_asset))
        col.prop(view_layer, "pass_cryptomatte_depth", text="Levels")


class SPLAT_TRACER_PT_object_visibility(SplatTracerPanel, bpy.types.Panel):
    """Mask (shadow catcher, holdout) and ray visibility, as Cycles reads them, inside
    Blender's Object > Visibility panel (Cycles' own copy hides for other engines)."""
    bl_label = "Ray Visibility"
    bl_context = "object"
    bl_parent_id = "OBJECT_PT_visibility"
    context_member = "object"

    @classmethod
    def poll(cls, context):
        obj = context.object
        return super().poll(context) and obj.type not in {"CAMERA", "LIGHT", "EMPTY"}

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        obj = context.object
        col = layout.column(heading="Mask")
        col.prop(obj, "is_shadow_catcher")
        col.prop(obj, "is_holdout")
        col = layout.column(heading="Ray Visibility")
        for prop, text in (("visible_camera", "Camera"), ("visible_diffuse", "Diffuse"), ("visible_glossy", "Glossy"),
                           ("visible_transmission", "Transmission"), ("visible_shadow", "Shadow")):
            col.prop(obj, prop, text=text)
        layout.prop(obj, "pass_index")


class SPLAT_TRACER_PT_light(SplatTracerPanel, bpy.types.Panel):
    """The lamp's settings, the one Light panel (Blender's own, DATA_PT_light, is not opened:
    it holds only a second type selector). Drawn as Cycles' Light panel draws them, less what
    the engine does not render."""
    bl_label = "Light"
    bl_context = "data"
    context_member = "light"

    def draw(self, context):
        layout = self.layout
        light = context.light
        layout.row().prop(light, "type", expand=True)
        layout.use_property_split = True
        col = layout.column()
        row = col.column(align=True, heading="Temperature").row(align=True)
        row.use_property_decorate = False
        row.prop(light, "use_temperature", text="")
        sub = row.row()
        sub.active = light.use_temperature
        sub.prop(light, "temperature", text="")
        row.prop_decorator(light, "temperature")
        col.prop(light, "color", text="Tint" if light.use_temperature else "Color")
        layout.separator()
        col = layout.column()
        col.prop(light, "energy", text="Strength" if light.type == "SUN" else "Power")
        col.prop(light, "exposure")
        if light.type != "SUN":
            col.prop(light, "normalize")  # off is said in the render report (rendered as on)
        layout.separator()
        col = layout.column()
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
            col.prop(light, "show_cone")
        col.prop(light, "use_shadow", text="Cast Shadow")


def _draw_slot(layout, settings, name: str) -> None:
    """One A/B slot: its preset, switches, epsilon, kernel, crease angle and radius factor."""
    box = layout.box()
    row = box.row(align=True)
    row.label(text=f"Settings {name}")
    op = row.operator("splat_tracer.ab_copy", text="", icon="IMPORT")
    op.slot, op.direction = name, "FROM_SCENE"
    op = row.operator("splat_tracer.ab_copy", text="", icon="EXPORT")
    op.slot, op.direction = name, "TO_SCENE"
    col = box.column(align=True)
    col.prop(settings, "method", text="")
    # The switches of render.method.SWITCHES in the order the rules act along a ray, as the
    # Visibility panel shows them (a test checks that both draw every switch).
    for key in ("use_wrong_hit_elimination", "use_far_phase", "use_near_phase", "use_nearest_centre",
                "use_normal_interpolation"):
        col.prop(settings, key)
    col.prop(settings, "kernel", text="")
    col.prop(settings, "crease_angle")
    col.prop(settings, "epsilon")
    col.prop(settings, "radius_factor")


class SPLAT_TRACER_PT_motion_blur(SplatTracerPanel, bpy.types.Panel):
    """Render > Motion Blur, the settings Cycles' panel shows (Cycles' own hides for other
    engines), read where Cycles reads them (blender/export/motion.py)."""
    bl_label = "Motion Blur"
    bl_context = "render"
    bl_options = {"DEFAULT_CLOSED"}

    def draw_header(self, context):
        self.layout.prop(context.scene.render, "use_motion_blur", text="")

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        rd = context.scene.render
        layout.active = rd.use_motion_blur
        col = layout.column()
        col.prop(rd, "motion_blur_position", text="Position")
        col.prop(rd, "motion_blur_shutter")
        cycles = getattr(context.scene, "cycles", None)
        if cycles is not None and hasattr(cycles, "rolling_shutter_type"):
            col.separator()
            col.prop(cycles, "rolling_shutter_type", text="Rolling Shutter")
            sub = col.column()
            sub.active = cycles.rolling_shutter_type != "NONE"
            sub.prop(cycles, "rolling_shutter_duration")
        # The view layer's own switch (Cycles draws it in its View Layer > Filter panel,
        # which it keeps to itself): Cycles blurs a layer when both are on.
        col.separator()
        col.prop(context.view_layer, "use_motion_blur", text="View Layer")
        layout.label(text="Final renders only: the viewport shows no blur (as Cycles')")


class SPLAT_TRACER_PT_motion_blur_curve(SplatTracerPanel, bpy.types.Panel):
    bl_label = "Shutter Curve"
    bl_context = "render"
    bl_parent_id = "SPLAT_TRACER_PT_motion_blur"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        rd = context.scene.render
        layout.active = rd.use_motion_blur
        layout.template_curve_mapping(rd, "motion_blur_shutter_curve")


class SPLAT_TRACER_PT_object_motion_blur(SplatTracerPanel, bpy.types.Panel):
    """Object > Motion Blur: Cycles' per-object switch and steps (object.cycles), which the
    engine reads as Cycles does; Deformation is shown, and said unrendered in the report."""
    bl_label = "Motion Blur"
    bl_context = "object"
    bl_options = {"DEFAULT_CLOSED"}
    context_member = "object"

    @classmethod
    def poll(cls, context):
        obj = context.object
        return (super().poll(context) and hasattr(obj, "cycles")
                and (obj.type not in {"LIGHT", "EMPTY", "LIGHT_PROBE", "SPEAKER", "ARMATURE", "LATTICE"}
                     or (obj.instance_type == "COLLECTION" and obj.instance_collection is not None)))

    def draw_header(self, context):
        self.layout.active = context.scene.render.use_motion_blur
        self.layout.prop(context.object.cycles, "use_motion_blur", text="")

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        obj = context.object
        layout.active = context.scene.render.use_motion_blur and obj.cycles.use_motion_blur
        col = layout.column()
        col.prop(obj.cycles, "motion_steps", text="Steps")
        if obj.type != "CAMERA":
            col.prop(obj.cycles, "use_deform_motion", text="Deformation")


class SPLAT_TRACER_PT_camera_panorama(SplatTracerPanel, bpy.types.Panel):
    """A panoramic camera's settings (Blender's Lens panel draws them for Cycles only), the
    ones the engine reads (blender/export/scene.py camera_panorama)."""
    bl_label = "Panorama"
    bl_context = "data"
    bl_parent_id = "DATA_PT_lens"
    context_member = "camera"

    @classmethod
    def poll(cls, context):
        return super().poll(context) and context.camera.type == "PANO"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        cam = context.camera
        col = layout.column()
        col.prop(cam, "panorama_type")
        kind = cam.panorama_type
        if kind == "FISHEYE_EQUIDISTANT":
            col.prop(cam, "fisheye_fov")
        elif kind == "FISHEYE_EQUISOLID":
            col.prop(cam, "fisheye_lens", text="Lens")
            col.prop(cam, "fisheye_fov")
        elif kind == "EQUIRECTANGULAR":
            sub = col.column(align=True)
            sub.prop(cam, "latitude_min", text="Latitude Min")
            sub.prop(cam, "latitude_max", text="Max")
            sub = col.column(align=True)
            sub.prop(cam, "longitude_min", text="Longitude Min")
            sub.prop(cam, "longitude_max", text="Max")
        elif kind != "MIRRORBALL":
            col.label(text="Not rendered by Splat Tracer", icon="ERROR")


class SPLAT_TRACER_PT_viewport_ab(bpy.types.Panel):
    """The viewport's live A/B comparison, in the 3D View's sidebar (N)."""
    bl_label = "A/B Comparison"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Splat Tracer"

    @classmethod
    def poll(cls, context):
        return context.engine == ENGINE

    def draw(self, context):
        layout = self.layout
        props = context.scene.splat_tracer.ab
        shading = getattr(context.space_data, "shading", None)
        if shading is not None and shading.type != "RENDERED":
            layout.label(text="Shows in Rendered shading (Z)", icon="INFO")
        layout.row().prop(props, "mode", expand=True)
        row = layout.row(align=True)
        row.operator("splat_tracer.ab_flip", icon="ARROW_LEFTRIGHT")
        row.prop(props, "show_difference", toggle=True)
        row = layout.row(align=True)
        row.active = props.mode == "SPLIT"
        row.prop(props, "split", slider=True)
        row.operator("splat_tracer.ab_split_drag", text="", icon="ARROW_LEFTRIGHT")
        _draw_slot(layout, props.a, "A")
        _draw_slot(layout, props.b, "B")
        if props.a.radius_factor != props.b.radius_factor:
            layout.label(text="Two radius factors: the clouds are built twice", icon="ERROR")


def draw_viewport_header(self, context):
    """A/B buttons in the 3D View's header, in Rendered shading with this engine."""
    shading = getattr(context.space_data, "shading", None)
    if context.engine != ENGINE or shading is None or shading.type != "RENDERED":
        return
    props = context.scene.splat_tracer.ab
    row = self.layout.row(align=True)
    row.prop(props, "mode", expand=True)
    row.prop(props, "show_difference", text="", icon="IMAGE_REFERENCE")


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
    context_member = "material"

    def draw(self, context):
        _draw_surface(self.layout, context.material, "OUTPUT_MATERIAL", "Surface")


class SPLAT_TRACER_PT_material_settings(SplatTracerPanel, bpy.types.Panel):
    """Material > Settings: the material's Pass Index and the Cycles settings the engine
    reads where Cycles keeps them (material.cycles): Emission Sampling and Bump Map
    Correction."""
    bl_label = "Settings"
    bl_context = "material"
    bl_options = {"DEFAULT_CLOSED"}
    context_member = "material"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        material = context.material
        col = layout.column()
        col.prop(material, "pass_index")
        cycles = getattr(material, "cycles", None)
        if cycles is not None:
            col.prop(cycles, "emission_sampling")
            if hasattr(cycles, "use_bump_map_correction"):  # Cycles' setting from Blender 4.1 on
                col.prop(cycles, "use_bump_map_correction")


class SPLAT_TRACER_PT_world(SplatTracerPanel, bpy.types.Panel):
    bl_label = "Surface"
    bl_context = "world"
    context_member = "world"

    def draw(self, context):
        _draw_surface(self.layout, context.world, "OUTPUT_WORLD", "Surface")


class SPLAT_TRACER_PT_world_ray_visibility(SplatTracerPanel, bpy.types.Panel):
    """Cycles' world ray visibility (the Cycles add-on's property group), less Volume
    Scatter: no volumes are rendered."""
    bl_label = "Ray Visibility"
    bl_context = "world"
    bl_options = {"DEFAULT_CLOSED"}
    context_member = "world"

    @classmethod
    def poll(cls, context):
        return super().poll(context) and hasattr(context.world, "cycles_visibility")

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        visibility = context.world.cycles_visibility
        col = layout.column()
        for prop in ("camera", "diffuse", "glossy", "transmission"):
            col.prop(visibility, prop)


classes = (SPLAT_TRACER_PT_render, SPLAT_TRACER_PT_sampling, SPLAT_TRACER_PT_visibility,
           SPLAT_TRACER_PT_light_paths, SPLAT_TRACER_PT_performance,
           SPLAT_TRACER_PT_object, SPLAT_TRACER_PT_object_visibility, SPLAT_TRACER_PT_passes,
           SPLAT_TRACER_PT_passes_cryptomatte,
           SPLAT_TRACER_PT_light, SPLAT_TRACER_PT_motion_blur, SPLAT_TRACER_PT_motion_blur_curve,
           SPLAT_TRACER_PT_object_motion_blur, SPLAT_TRACER_PT_camera_panorama, SPLAT_TRACER_PT_material,
           SPLAT_TRACER_PT_material_settings,
           SPLAT_TRACER_PT_world,
           SPLAT_TRACER_PT_world_ray_visibility, SPLAT_TRACER_PT_viewport_ab,
           SPLAT_TRACER_PT_passes_light_groups, SPLAT_TRACER_PT_object_light_group,
           SPLAT_TRACER_PT_world_light_group)

# Blender's engine-agnostic panels opened for this engine: the ones whose settings apply to it
# (honoured, said in the render report, or applied by Blender: output, colour management,
# object data, physics), as Cycles' add-on keeps its list (cycles/ui.py get_panels). Names, or
# fnmatch patterns for whole families. Left out on purpose: DATA_PT_light (a second light-type
# selector; SPLAT_TRACER_PT_light is the one Light panel), DATA_PT_spot (in that panel),
# DATA_PT_preview and MATERIAL_PT_preview (no preview renders: bl_use_preview), the volume and
# light-probe render settings, Freestyle and Grease Pencil render settings (not offered by this engine),
# EEVEE_MATERIAL_PT_viewport_settings (EEVEE's material settings) and OBJECT_PT_shading (an
# empty parent for engines' shading settings). tests/blender/test_panels.py checks that every
# panel opened is here and that none shows a setting the settings audit lists as not rendered.
GENERIC_PANELS = (
    # Render and Output properties
    "RENDER_PT_color_management", "RENDER_PT_color_management_*", "RENDER_PT_simplify",
    "RENDER_PT_simplify_render", "RENDER_PT_simplify_viewport", "RENDER_PT_format", "RENDER_PT_frame_range",
    "RENDER_PT_time_stretching", "RENDER_PT_stereoscopy", "RENDER_PT_output", "RENDER_PT_output_*",
    "RENDER_PT_encoding", "RENDER_PT_encoding_*", "RENDER_PT_stamp", "RENDER_PT_stamp_*",
    "RENDER_PT_post_processing",
    # View layer, object, world, material
    "VIEWLAYER_PT_layer", "VIEWLAYER_PT_context_layer", "OBJECT_PT_visibility", "OBJECT_PT_custom_props",
    "WORLD_PT_context_world", "WORLD_PT_animation", "WORLD_PT_custom_props", "MATERIAL_PT_animation",
    "MATERIAL_PT_custom_props", "MATERIAL_PT_freestyle_line",
    # Camera: Depth of Field is honoured as Cycles does (Cycles opens its own copy); the stereo
    # eyes' cameras are rendered (Blender gives each view's to the engine)
    "CAMERA_PT_presets", "CAMERA_PT_safe_areas_presets", "DATA_PT_context_camera", "DATA_PT_camera",
    "DATA_PT_lens", "DATA_PT_camera_dof", "DATA_PT_camera_dof_aperture", "DATA_PT_camera_stereoscopy",
    "DATA_PT_camera_display",
    "DATA_PT_camera_display_composition_guides", "DATA_PT_camera_safe_areas",
    "DATA_PT_camera_safe_areas_center_cut", "DATA_PT_camera_background_image", "DATA_PT_camera_animation",
    "DATA_PT_custom_props_camera",
    # Lamps: the ID, animation and custom properties (the settings: SPLAT_TRACER_PT_light)
    "DATA_PT_context_light", "DATA_PT_light_animation", "DATA_PT_custom_props_light",
    # Object data the engine renders or Blender evaluates into it: meshes, point clouds,
    # curves, their attributes; speakers (sound); a volume's grids (the object is said as
    # not rendered)
    "DATA_PT_context_mesh", "DATA_PT_context_pointcloud", "DATA_PT_context_curves", "DATA_PT_context_speaker",
    "DATA_PT_context_volume", "DATA_PT_context_lightprobe", "DATA_PT_vertex_groups", "DATA_PT_shape_keys",
    "DATA_PT_uv_texture", "DATA_PT_vertex_colors", "DATA_PT_customdata", "DATA_PT_mesh_attributes",
    "DATA_PT_pointcloud_attributes", "DATA_PT_CURVES_attributes", "DATA_PT_curves_surface",
    "DATA_PT_texture_space", "DATA_PT_remesh", "DATA_PT_mesh_animation", "DATA_PT_curves_animation",
    "DATA_PT_volume_animation", "DATA_PT_volume_file", "DATA_PT_volume_grids", "DATA_PT_speaker",
    "DATA_PT_distance", "DATA_PT_cone", "DATA_PT_speaker_animation", "DATA_PT_custom_props_*",
    # Particles, physics and textures: Blender simulates and evaluates them into the scene
    "PARTICLE_PT_*", "PHYSICS_PT_*", "TEXTURE_PT_*", "NODE_PT_texture_mapping",
    # Custom properties elsewhere
    "STRIP_PT_custom_props", "SEQUENCER_PT_custom_props",
)
_extended_panels = []


def generic_panel_included(name: str) -> bool:
    return any(fnmatch.fnmatchcase(name, pattern) for pattern in GENERIC_PANELS)


def _extend_builtin_panels():
    for panel in bpy.types.Panel.__subclasses__():
        engines = getattr(panel, "COMPAT_ENGINES", None)
        if isinstance(engines, set) and ENGINE not in engines and generic_panel_included(panel.__name__):
            engines.add(ENGINE)
            _extended_panels.append(panel)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    _extend_builtin_panels()
    bpy.types.VIEW3D_HT_header.append(draw_viewport_header)


def unregister():
    bpy.types.VIEW3D_HT_header.remove(draw_viewport_header)
    for panel in _extended_panels:
        panel.COMPAT_ENGINES.discard(ENGINE)
    _extended_panels.clear()
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
