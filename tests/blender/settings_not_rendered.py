"""The settings the audit (test_settings_audit.py) does not expect to change a render, each
with its reason; docs/settings.md is made from this file (`python
tests/blender/settings_not_rendered.py > docs/settings.md`, a test checks the two agree).
"""
from __future__ import annotations

import fnmatch
from dataclasses import dataclass

# The structs the audit walks (test_settings_audit.Audit.owners), as an artist reaches them;
# spot_light, area_light and sun_light: the lamp turned into that type, the settings its own RNA
# class adds to a point lamp's.
OWNERS = ("render", "cycles", "view_settings", "display_settings", "view_layer", "view_layer.cycles", "object",
          "object.cycles", "light", "spot_light", "area_light", "sun_light",
          "light.cycles", "world", "world.cycles", "world.light_settings",
          "world.mist_settings", "world.cycles_visibility", "material", "material.cycles", "camera", "camera.dof",
          "camera.stereo")


@dataclass(frozen=True)
class Entry:
    owner: str
    names: tuple    # property identifiers, fnmatch patterns allowed
    kind: str       # a key of KINDS
    reason: str
    # The Blender versions having these settings, where not every version the matrix covers
    # (tests/release/test_blender_versions.py): since the first version with them, before the
    # first without them, (major, minor).
    since: tuple = ()
    before: tuple = ()

    def versions(self) -> str:
        """The version note docs/settings.md shows ("" for every version)."""
        dotted = [".".join(map(str, v)) for v in (self.since, self.before)]
        if self.since and self.before:
            only = self.before == (self.since[0], self.since[1] + 1)
            return f" (Blender {dotted[0]} only)" if only else f" (Blender {dotted[0]} to before {dotted[1]})"
        return f" (Blender {dotted[0]} and later)" if self.since else f" (before Blender {dotted[1]})" if self.before else ""


KINDS = {
    "blender": "Applied by Blender, not by the render engine",
    "viewport": "Viewport, interface or file settings: no render engine reads them for a final frame",
    "cycles": "Cycles' internals: how Cycles computes, not what it computes",
    "unsupported": "Not rendered by Splat Tracer",
    "dependent": "Honoured, but changes nothing in the audit's scene, where the feature it tunes is off "
                 "(its own test renders it on)",
}

B, V, C, U, D = "blender", "viewport", "cycles", "unsupported", "dependent"
ENTRIES = (
    # -- scene.render --------------------------------------------------------------------
    Entry("render", ("fps", "fps_base", "frame_map_old", "frame_map_new"), B,
          "Frame rate and time remapping: Blender sets the frame the engine renders; a still frame is the same"),
    Entry("render", ("ppm_factor", "ppm_base"), B, "Print resolution: Blender writes it into the file", since=(4, 5)),
    Entry("render", ("use_new_cpu_compositor",), B, "Which compositor Blender runs on the engine's result",
          since=(4, 3), before=(4, 4)),
    Entry("render", ("dither_intensity", "use_crop_to_border", "use_placeholder", "use_overwrite",
                     "use_file_extension", "filepath", "use_compositing", "use_sequencer",
                     "use_sequencer_override_scene_strip", "use_single_layer", "use_stamp*", "stamp_*",
                     "metadata_input", "use_freestyle", "line_thickness_mode", "line_thickness", "compositor_*",
                     "use_render_cache", "sequencer_gl_preview"), B,
          "Output, compositing, sequencer, metadata stamps and Freestyle: Blender applies them to the engine's "
          "result, as to Cycles'"),
    Entry("render", ("engine",), B, "Chooses the render engine itself"),
    Entry("render", ("preview_pixel_size", "use_lock_interface"), V, "The viewport's pixel size; the interface lock"),
    Entry("render", ("threads", "threads_mode", "use_persistent_data"), C,
          "Performance only: the engine uses the threads and keeps the geometry between frames (Persistent "
          "Data), and the image is the same"),
    Entry("render", ("hair_type", "hair_subdiv", "use_high_quality_normals", "use_simplify", "simplify_*",
                     "use_simplify_normals"), B,
          "Hair display and Simplify: Blender applies them to the evaluated scene (subdivision levels, child "
          "particles) the engine reads"),
    Entry("render", ("save_output",), B, "Whether Blender writes an animation's frames to disk", since=(5, 2)),
    Entry("render", ("use_texture_cache", "use_auto_generate_texture_cache", "anisotropic_filter"), C,
          "Cycles' texture cache and its filtering: how Cycles loads and filters image tiles (memory, "
          "aliasing); the engine reads each image whole, and a pixel's samples average what it covers",
          since=(5, 2)),
    Entry("render", ("bake_*", "use_bake_*"), C,
          "Blender's older bake settings: the engine never bakes", before=(5, 0)),
    # -- scene.cycles --------------------------------------------------------------------
    Entry("cycles", ("name",), V, "The property group's name, not a setting"),
    Entry("cycles", ("device", "shading_system", "denoising_use_gpu", "preview_denoising_use_gpu", "debug_*",
                     "use_auto_tile", "tile_size", "texture_limit", "texture_limit_render", "use_camera_cull",
                     "camera_cull_margin", "use_distance_cull", "distance_cull_margin", "bake_type"), C,
          "Device, OSL, GPU, tiles, texture memory limits, culling, BVH and debug options, baking: how and where "
          "Cycles computes (the engine runs on the CPU, never bakes, and culls nothing)"),
    Entry("cycles", ("sampling_pattern", "scrambling_distance", "preview_scrambling_distance",
                     "auto_scrambling_distance", "light_sampling_threshold", "direct_light_sampling_type",
                     "use_light_tree", "min_light_bounces", "min_transparent_bounces", "use_guiding",
                     "use_deterministic_guiding", "guiding_*", "use_surface_guiding", "surface_guiding_probability",
                     "use_volume_guiding", "volume_guiding_probability", "use_guiding_direct_light",
                     "use_guiding_mis_weights"), C,
          "Cycles' sampling strategy (patterns, light tree, path guiding, Russian roulette): they change "
          "Cycles' noise, not what it converges to; the engine has its own sampling"),
    Entry("cycles", ("preview_pause", "preview_samples", "use_preview_adaptive_sampling", "preview_adaptive_*",
                     "use_preview_denoising", "preview_denois*", "volume_preview_step_rate", "preview_dicing_rate"), V,
          "The viewport's settings (the engine's viewport reads its samples and adaptive sampling; the audit "
          "renders F12 frames)"),
    Entry("cycles", ("denoiser",), C,
          "Which denoiser Cycles runs: the engine denoises with OpenImageDenoise on the CPU, and says so when "
          "OptiX is set (test_unhonoured_settings.py); without an NVIDIA GPU OptiX cannot be chosen"),
    Entry("cycles", ("volume_bounces", "volume_step_rate", "volume_max_steps"), U,
          "Volumes are not rendered (a material's Volume output is said where it is ignored)"),
    Entry("cycles", ("volume_biased",), U, "Volumes are not rendered", since=(5, 0)),
    Entry("cycles", ("dicing_rate", "max_subdivisions", "offscreen_dicing_scale"), U,
          "Adaptive subdivision (Cycles' experimental feature set) is not used: meshes render as Blender "
          "evaluates them"),
    Entry("cycles", ("ao_bounces", "ao_bounces_render", "fast_gi_method"), U,
          "Settings of Fast GI, which the engine does not use (said)"),
    Entry("cycles", ("sample_offset",), U, "Settings of Sample Subset, which the engine does not use (said)"),
    Entry("cycles", ("sample_subset_length",), U, "Settings of Sample Subset, which the engine does not use (said)",
          since=(4, 4)),
    Entry("cycles", ("use_layer_samples",), U,
          "Acts with a view layer's Samples override, which the engine does not use (said)"),
    Entry("cycles", ("filter_width",), C,
          "Not shown by Cycles' panels: the Pixel Filter's width is `render.filter_size`, which the engine "
          "reads"),
    Entry("cycles", ("film_transparent_roughness",), U,
          "Acts with Transparent Glass, which the engine does not use (said)"),
    Entry("cycles", ("feature_set",), U,
          "Cycles' Experimental feature set: it enables adaptive subdivision, which is not used (meshes render "
          "as Blender evaluates them)", before=(5, 0)),
    Entry("cycles", ("texture_resolution",), V, "The viewport's texture resolution", since=(5, 2)),
    Entry("cycles", ("texture_resolution_render",), U,
          "Render Texture Resolution: images are read at their full resolution (said when not 1)", since=(5, 2)),
    Entry("cycles", ("use_pixel_jitter",), C,
          "How Cycles places samples within a pixel (one jitter per frame, for temporal denoisers); the "
          "engine's own samples cover each pixel", since=(5, 2)),
    # -- colour management ---------------------------------------------------------------
    Entry("view_settings", ("*",), B,
          "Colour management: Blender applies the view transform, look, exposure, gamma, curves and white "
          "balance to the engine's scene-linear result (the engine's viewport applies exposure and gamma)"),
    Entry("display_settings", ("*",), B, "Colour management: Blender's display transform"),
    # -- view layer ----------------------------------------------------------------------
    Entry("view_layer", ("name", "active_aov_index", "active_lightgroup_index"), V,
          "The layer's name and the selection in its AOV and light-group lists"),
    Entry("view_layer", ("use",), B, "Blender renders the view layer or skips it"),
    Entry("view_layer", ("use_pass_combined",), B, "Combined is always written"),
    Entry("view_layer", ("use_freestyle",), B, "Freestyle lines: Blender draws them over the engine's result"),
    Entry("view_layer", ("pass_cryptomatte_depth",), D,
          "Cryptomatte Levels: the layers written when a Cryptomatte pass is on (tests/blender/test_cryptomatte.py)"),
    Entry("view_layer", ("use_pass_cryptomatte_accurate",), C,
          "Cycles does not read it (no panel shows it in 5.0); the engine does as Cycles"),
    Entry("view_layer", ("use_volumes",), U, "Volumes are not rendered (said where a material has one)"),
    Entry("view_layer", ("use_strand", "use_ao"), U,
          "Hair strands as strands and the legacy AO filter: not rendered by Cycles either"),
    Entry("view_layer", ("use_grease_pencil",), U,
          "Grease Pencil: not rendered by Cycles either (Blender draws it over the result)", since=(4, 5)),
    Entry("view_layer.cycles", ("name",), V, "The property group's name, not a setting"),
    Entry("view_layer.cycles", ("denoising_pass_follow_reflections", "denoising_pass_use_albedo_roughness_weighting"),
          U, "How Cycles makes its denoising guides: the engine's are the first hit's Diffuse Color and Normal "
          "(tests/blender/test_denoise.py)", since=(5, 2)),
    # -- objects -------------------------------------------------------------------------
    Entry("object", ("name", "use_fake_user", "use_extra_user", "is_runtime_data", "tag", "active_material_index",
                     "lock_*", "empty_*", "show_*", "use_empty_image_alpha", "hide_viewport", "hide_select",
                     "hide_probe_*", "display_type", "display_bounds_type",
                     "use_grease_pencil_lights", "use_shape_key_edit_mode", "use_mesh_mirror_*",
                     "active_shape_key_index", "active_selection_set", "use_camera_lock_parent"), V,
          "Names, data-block flags, viewport display, locks, selection and editing: no engine renders them"),
    Entry("object", ("hide_surface_pick",), V, "Selection in the viewport", since=(5, 0)),
    Entry("object", ("use_parent_final_indices",), B,
          "Vertex parenting to the evaluated mesh: Blender evaluates it into the object's matrix", since=(4, 5)),
    Entry("object", ("parent_type", "parent_vertices", "parent_bone", "track_axis",
                     "up_axis", "rotation_mode", "rotation_quaternion", "rotation_axis_angle",
                     "delta_rotation_quaternion", "matrix_parent_inverse", "instance_type",
                     "use_instance_vertices_rotation", "use_instance_faces_scale", "instance_faces_scale",
                     "add_rest_position_attribute", "use_simulation_cache", "show_instancer_for_render",
                     "show_only_shape_key"), B,
          "Parenting, rotation modes, instancing and shape keys: Blender evaluates them into the objects, "
          "matrices and instances the engine renders (no effect on the audit's unparented objects)"),
    Entry("object", ("color",), U,
          "Acts only through a material's Object Info node (what the engine makes of a material's nodes is "
          "said where it differs from Cycles)"),
    Entry("object", ("visible_volume_scatter",), U, "Volumes are not rendered"),
    Entry("object", ("lightgroup",), D,
          "The object's light group: its emission goes to that group's Combined_<group> pass, which the view "
          "layer has only when it holds the group (none in the audit's scene; tests/blender/test_light_passes.py)"),
    Entry("object", ("shadow_terminator_*",), U,
          "EEVEE's shadow terminator offsets; the engine's shading has none (Cycles' own are "
          "`object.cycles.shadow_terminator_*`)", since=(4, 5)),
    Entry("object", ("parent_bone_head_tail_factor",), B,
          "Where on its parent bone an object hangs: Blender evaluates it into the object's matrix", since=(5, 2)),
    Entry("object", ("visible_raycast",), U,
          "Acts only through the Raycast shader node, which the engine does not evaluate (what the engine "
          "makes of a material's nodes is said where it differs from Cycles)", since=(5, 2)),
    Entry("object.cycles", ("name",), V, "The property group's name, not a setting"),
    Entry("object.cycles", ("use_adaptive_subdivision", "dicing_rate"), U,
          "Adaptive subdivision is not used: meshes render as Blender evaluates them", before=(5, 0)),
    Entry("object.cycles", ("use_camera_cull", "use_distance_cull"), C,
          "Culling, an optimisation the engine does not make (it renders every object)"),
    Entry("object.cycles", ("ao_distance",), U, "Acts with Fast GI only, which the engine does not use (said)"),
    Entry("object.cycles", ("is_caustics_caster", "is_caustics_receiver"), U,
          "Shadow caustics (Cycles' manifold next-event estimation) are not rendered"),
    Entry("object.cycles", ("shadow_terminator_offset", "shadow_terminator_geometry_offset"), U,
          "Cycles' shadow terminator offsets for low-poly smooth meshes: the engine's shading has none"),
    # -- lamps ---------------------------------------------------------------------------
    Entry("light", ("name", "use_fake_user", "use_extra_user", "is_runtime_data", "tag"), V,
          "Name and data-block flags"),
    Entry("light", ("shadow_buffer_clip_start", "shadow_filter_radius", "shadow_maximum_resolution",
                    "use_shadow_jitter", "shadow_jitter_overblur", "use_absolute_resolution", "use_custom_distance",
                    "cutoff_distance"), C, "EEVEE's shadow maps and light distance: not read by Cycles"),
    Entry("light", ("volume_factor",), U, "Volumes are not rendered"),
    Entry("light", ("use_contact_shadow", "contact_shadow_*", "shadow_buffer_bias", "shadow_color"), C,
          "EEVEE Legacy's shadow settings: not read by Cycles", before=(4, 3)),
    Entry("light", ("use_nodes",), U,
          "The lamp's node tree: a tree beyond the default Emission is said as ignored"),
    Entry("light.cycles", ("name",), V, "The property group's name, not a setting"),
    Entry("light.cycles", ("use_multiple_importance_sampling",), C,
          "Cycles' sampling strategy for the lamp: changes noise, not what it converges to"),
    Entry("light.cycles", ("is_caustics_light",), U, "Shadow caustics are not rendered"),
    Entry("spot_light", ("show_cone",), V, "Viewport display of the cone"),
    Entry("spot_light", ("use_square",), C, "A square spot cone: EEVEE only, Cycles' spots are round"),
    Entry("sun_light", ("shadow_cascade_*",), C, "EEVEE's cascaded shadow maps"),
    # -- world ---------------------------------------------------------------------------
    Entry("world", ("name", "use_fake_user", "use_extra_user", "is_runtime_data", "tag", "use_nodes", "color"), V,
          "Name, data-block flags, and the world's viewport colour (the render reads the world's node tree)"),
    Entry("world", ("use_eevee_finite_volume", "probe_resolution", "sun_threshold", "sun_angle", "use_sun_shadow",
                    "sun_shadow_*", "use_sun_shadow_jitter"), C, "EEVEE's world lighting settings"),
    Entry("world", ("lightgroup",), D,
          "The world's light group: its light goes to that group's Combined_<group> pass, which the view layer "
          "has only when it holds the group (none in the audit's scene; tests/blender/test_light_passes.py)"),
    Entry("world.cycles", ("name",), V, "The property group's name, not a setting"),
    Entry("world.cycles", ("sampling_method", "sample_map_resolution"), C,
          "How Cycles importance-samples the world: changes noise, not what it converges to"),
    Entry("world.cycles", ("volume_sampling", "volume_interpolation", "volume_step_size"), U,
          "Volumes are not rendered"),
    Entry("world.cycles", ("is_caustics_light",), U, "Shadow caustics are not rendered"),
    Entry("world.cycles", ("homogeneous_volume",), U, "Volumes are not rendered", before=(5, 0)),
    Entry("world.cycles", ("use_shadows",), U,
          "Shadows off (the world's light unshadowed) is not honoured: said when off", since=(5, 2)),
    Entry("world.light_settings", ("ao_factor",), U,
          "Fast GI's AO factor, which the engine does not use (said); the engine's own AO sky light has its "
          "own settings"),
    Entry("world.light_settings", ("distance",), D,
          "The Ambient Occlusion pass's distance: read when that pass is on (off in the audit's scene; "
          "tests/blender/test_light_passes.py), and by an Ambient Occlusion node whose Distance is 0 and "
          "unlinked, as Cycles (tests/blender/test_node_raytrace.py)"),
    Entry("world.mist_settings", ("use_mist", "intensity", "height"), C,
          "Not read by Cycles either: its Mist pass takes Start, Depth and Falloff"),
    Entry("world.cycles_visibility", ("name",), V, "The property group's name, not a setting"),
    Entry("world.cycles_visibility", ("scatter",), U, "Volumes are not rendered (said when switched off)"),
    Entry("world.cycles_visibility", ("shadow",), U,
          "Not shown in Cycles' panels (its world Ray Visibility has no Shadow); not read"),
    # -- materials -----------------------------------------------------------------------
    Entry("material", ("name", "use_fake_user", "use_extra_user", "is_runtime_data", "tag", "use_nodes",
                       "diffuse_color", "specular_color", "roughness", "specular_intensity", "metallic",
                       "preview_render_type", "use_preview_world", "paint_active_slot", "paint_clone_slot"), V,
          "Name, data-block flags, the viewport display colours, preview and texture paint: the render reads "
          "the material's node tree"),
    Entry("material", ("surface_render_method", "blend_method", "alpha_threshold", "use_transparency_overlap",
                       "show_transparent_back", "use_backface_culling", "use_backface_culling_shadow",
                       "use_backface_culling_lightprobe_volume", "use_transparent_shadow", "use_raytrace_refraction",
                       "use_screen_refraction", "use_sss_translucency", "refraction_depth", "thickness_mode",
                       "use_thickness_from_shadow", "max_vertex_displacement"), C,
          "EEVEE's material settings: not read by Cycles"),
    Entry("material", ("line_color", "line_priority"), B, "Line Art: Blender's Grease Pencil modifier"),
    Entry("material", ("displacement_method", "volume_intersection_method"), U,
          "Displacement and volumes are not rendered (a material's Displacement and Volume outputs are said "
          "where ignored)"),
    Entry("material", ("shadow_method",), C, "EEVEE Legacy's material shadow mode: not read by Cycles", before=(4, 3)),
    Entry("material.cycles", ("name",), V, "The property group's name, not a setting"),
    Entry("material.cycles", ("homogeneous_volume",), U, "Volumes are not rendered", before=(5, 0)),
    Entry("material.cycles", ("emission_sampling",), C,
          "How Cycles samples emissive meshes: changes noise, not what it converges to"),
    Entry("material.cycles", ("use_bump_map_correction",), D,
          "Cycles' bump shadowing term where nodes drive the normal (Bump, Normal Map), left out when off as in "
          "Cycles; the audit's material has no such node. Its bending of normals whose reflection would leave "
          "the surface is not done"),
    Entry("material.cycles", ("volume_sampling", "volume_interpolation", "volume_step_rate"), U,
          "Volumes are not rendered"),
    # -- cameras -------------------------------------------------------------------------
    Entry("camera", ("name", "use_fake_user", "use_extra_user", "is_runtime_data", "tag", "passepartout_alpha",
                     "display_size", "show_*", "lens_unit"), V,
          "Name, data-block flags, viewport display and the lens's unit (the lens is the same)"),
    Entry("camera", ("composition_guide_color",), V, "Viewport display of the composition guides", since=(5, 0)),
    Entry("camera", ("fisheye_polynomial_*",), U,
          "The Fisheye Lens Polynomial panorama is not rendered: the frame fails with a message naming the type"),
    Entry("camera", ("central_cylindrical_*",), U,
          "The Central Cylindrical panorama is not rendered: the frame fails with a message naming the type",
          since=(4, 3)),
    Entry("camera", ("custom_*",), U, "Custom (OSL script) cameras are not rendered: the frame fails with a message",
          since=(4, 5)),
    Entry("camera.dof", ("focus_subtarget",), B,
          "A bone of the focus object: Blender's focus distance follows it (no bone in the audit's scene)"),
    Entry("camera.stereo", ("use_spherical_stereo", "use_pole_merge", "pole_merge_angle_*"), U,
          "Cycles' spherical stereo and its pole merge (each ray its own eye offset) are not used: each eye is "
          "rendered with its whole camera moved (said for a panoramic camera)"),
)

# A value for settings whose generic change (test_settings_audit.changed_value) shows nothing
# in the audit's scene, though the engine honours the setting.
VALUES = {
    "render.border_min_x": 0.5, "render.border_min_y": 0.5, "render.border_max_x": 0.5, "render.border_max_y": 0.5,
    "cycles.time_limit": 1e-6,
    "cycles.adaptive_threshold": 0.5,
    "cycles.adaptive_min_samples": 40,
    "cycles.max_bounces": 0, "cycles.glossy_bounces": 0, "cycles.transmission_bounces": 0,
    "cycles.transparent_max_bounces": 0,
    "cycles.sample_clamp_direct": 0.01, "cycles.sample_clamp_indirect": 0.001,
    "area_light.shape": "DISK",
    "camera.sensor_fit": "VERTICAL",
    "camera.clip_end": 4.0,
    "camera.panorama_type": "MIRRORBALL",
    "camera.dof.aperture_blades": 5,
}

# Settings acting only in another mode: what is set first (before both renders).
_ADAPTIVE = {"cycles.samples": 64, "cycles.use_adaptive_sampling": True, "cycles.adaptive_threshold": 0.5}
_DOF = {"camera.dof.use_dof": True}
CONTEXT = {
    "render.use_border": {"render.border_max_x": 0.5},
    **{f"render.border_{b}": {"render.use_border": True} for b in ("min_x", "min_y", "max_x", "max_y")},
    "render.motion_blur_shutter": {"render.use_motion_blur": True},
    "render.motion_blur_position": {"render.use_motion_blur": True},
    # Motion blur: its settings act with it on (the audit's camera and cloud move).
    "cycles.rolling_shutter_type": {"render.use_motion_blur": True},
    "cycles.rolling_shutter_duration": {"render.use_motion_blur": True, "cycles.rolling_shutter_type": "TOP"},
    "view_layer.use_motion_blur": {"render.use_motion_blur": True},
    **{f"object.cycles.{p}": {"render.use_motion_blur": True}
       for p in ("use_motion_blur", "motion_steps", "use_deform_motion")},
    "render.filter_size": {"cycles.samples": 4},
    "cycles.pixel_filter_type": {"cycles.samples": 4},
    "cycles.time_limit": {"cycles.samples": 64},
    "cycles.use_adaptive_sampling": {k: v for k, v in _ADAPTIVE.items() if k != "cycles.use_adaptive_sampling"},
    "cycles.adaptive_threshold": {k: v for k, v in _ADAPTIVE.items() if k != "cycles.adaptive_threshold"},
    "cycles.adaptive_min_samples": _ADAPTIVE,
    "cycles.film_transparent_glass": {"render.film_transparent": True},
    "view_layer.cycles.use_denoising": {"cycles.use_denoising": True},
    "light.temperature": {"light.use_temperature": True},
    "light.cycles.is_portal": {"light.type": "AREA"},
    "light.use_soft_falloff": {"light.shadow_soft_size": 3.0},
    "area_light.size_y": {"area_light.shape": "RECTANGLE"},
    "camera.sensor_height": {"camera.sensor_fit": "VERTICAL"},
    "camera.ortho_scale": {"camera.type": "ORTHO"},
    "camera.panorama_type": {"camera.type": "PANO", "camera.panorama_type": "EQUIRECTANGULAR"},
    "camera.fisheye_fov": {"camera.type": "PANO", "camera.panorama_type": "FISHEYE_EQUIDISTANT"},
    "camera.fisheye_lens": {"camera.type": "PANO", "camera.panorama_type": "FISHEYE_EQUISOLID"},
    **{f"camera.{p}": {"camera.type": "PANO", "camera.panorama_type": "EQUIRECTANGULAR"}
       for p in ("latitude_min", "latitude_max", "longitude_min", "longitude_max")},
    **{f"camera.dof.{p}": _DOF for p in ("focus_distance", "aperture_fstop", "aperture_blades", "aperture_ratio")},
    "camera.dof.aperture_rotation": {**_DOF, "camera.dof.aperture_blades": 5},
    # Stereoscopy: its settings act with it on (each view compared, test_settings_audit.Audit.frame).
    "render.views_format": {"render.use_multiview": True},
    **{f"camera.stereo.{p}": {"render.use_multiview": True}
       for p in ("convergence_mode", "convergence_distance", "interocular_distance", "pivot")},
    # Denoising: its settings act with Cycles' Denoise on.
    **{f"cycles.denoising_{p}": {"cycles.use_denoising": True} for p in ("prefilter", "quality", "input_passes")},
}


# The series whose settings the version matrix's walk last checked against this list (bpy
# versions, PyPI's), said in docs/settings.md.
CHECKED = "bpy 4.2.23, 4.3.0, 4.4.0, 4.5.15, 5.1.2 and 5.2.3 (2026-11-27)"


def applies(entry: Entry, version: tuple) -> bool:
    """Whether `entry` is for a Blender `version` ((major, minor, ...), as bpy.app.version)."""
    v = tuple(version)[:2]
    return (not entry.since or v >= entry.since) and (not entry.before or v < entry.before)


def listed(key: str, version: tuple):
    """The entry listing setting `key` ('owner.prop') in a Blender `version`, or None."""
    owner, _, prop = key.rpartition(".")
    return next((e for e in ENTRIES if e.owner == owner and applies(e, version)
                 and any(fnmatch.fnmatchcase(prop, p) for p in e.names)), None)


def markdown() -> str:
    out = ["# Settings Splat Tracer does not render", "",
           "Generated from `tests/blender/settings_not_rendered.py` (the settings audit's lists, "
           "`tests/blender/test_settings_audit.py`); do not edit by hand.", "",
           "The audit walks every setting Blender's RNA gives these structs (the scene's `render`, "
           "Cycles' scene settings `cycles`, colour management, the view layer and its `cycles` group, "
           "objects, lamps of each type, the world with its mist and light settings, materials, the "
           "camera with its depth of field and stereo settings), changes each alone in a tiny render, "
           "and requires that the image or a pass changes, or that the render report says it "
           "([user-guide.md](user-guide.md#settings-the-engine-does-not-honour)). The settings below "
           "are the exceptions, each with its reason; every other one is honoured or said.", "",
           "The audit renders in the Blender the tests run (bpy 5.0.1). The version matrix "
           "(`tests/release/test_blender_versions.py`) runs the same walk in each Blender series it "
           "covers and fails on a setting that series has which the audit did not walk and which is "
           "not listed here for that version; an entry with versions is for those only. "
           f"Last checked: {CHECKED}.", ""]
    for kind, title in KINDS.items():
        out += [f"## {title}", "", "| Settings | Why |", "|---|---|"]
        for e in ENTRIES:
            if e.kind == kind:
                names = ", ".join(f"every `{e.owner}` setting" if n == "*" else f"`{e.owner}.{n}`" for n in e.names)
                out.append(f"| {names}{e.versions()} | {e.reason} |")
        out.append("")
    return "\n".join(out)


if __name__ == "__main__":
    print(markdown(), end="")
