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
    Entry("render", ("ppm_factor", "ppm_base", "fps", "fps_base", "frame_map_old", "frame_map_new"), B,
          "Frame rate, time remapping and print resolution: Blender sets the frame the engine renders "
          "and writes the file; a still frame is the same"),
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
    Entry("cycles", ("volume_bounces", "volume_step_rate", "volume_max_steps", "volume_biased"), U,
          "Volumes are not rendered (a material's Volume output is said where it is ignored)"),
    Entry("cycles", ("dicing_rate", "max_subdivisions", "offscreen_dicing_scale"), U,
          "Adaptive subdivision (Cycles' experimental feature set) is not used: meshes render as Blender "
          "evaluates them"),
    Entry("cycles", ("rolling_shutter_type", "rolling_shutter_duration"), U,
          "Acts with motion blur only, which the engine does not render (said)"),
    Entry("cycles", ("ao_bounces", "ao_bounces_render", "fast_gi_method"), U,
          "Settings of Fast GI, which the engine does not use (said)"),
    Entry("cycles", ("sample_offset", "sample_subset_length"), U,
          "Settings of Sample Subset, which the engine does not use (said)"),
    Entry("cycles", ("use_layer_samples",), U,
          "Acts with a view layer's Samples override, which the engine does not use (said)"),
    Entry("cycles", ("filter_width",), C,
          "Not shown by Cycles' panels: the Pixel Filter's width is `render.filter_size`, which the engine "
          "reads"),
    Entry("cycles", ("film_transparent_roughness",), U,
          "Acts with Transparent Glass, which the engine does not use (said)"),
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
    Entry("view_layer", ("use_grease_pencil", "use_strand", "use_ao"), U,
          "Grease Pencil, hair strands as strands, and the legacy AO filter: not rendered by Cycles either "
          "(Blender draws Grease Pencil over the result)"),
    Entry("view_layer", ("use_motion_blur",), U, "Acts with motion blur only, which the engine does not render (said)"),
    Entry("view_layer.cycles", ("name",), V, "The property group's name, not a setting"),
    # -- objects -------------------------------------------------------------------------
    Entry("object", ("name", "use_fake_user", "use_extra_user", "is_runtime_data", "tag", "active_material_index",
                     "lock_*", "empty_*", "show_*", "use_empty_image_alpha", "hide_viewport", "hide_select",
                     "hide_probe_*", "hide_surface_pick", "display_type", "display_bounds_type",
                     "use_grease_pencil_lights", "use_shape_key_edit_mode", "use_mesh_mirror_*",
                     "active_shape_key_index", "active_selection_set", "use_camera_lock_parent"), V,
          "Names, data-block flags, viewport display, locks, selection and editing: no engine renders them"),
    Entry("object", ("parent_type", "parent_vertices", "parent_bone", "use_parent_final_indices", "track_axis",
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
          "`object.cycles.shadow_terminator_*`)"),
    Entry("object.cycles", ("name",), V, "The property group's name, not a setting"),
    Entry("object.cycles", ("use_motion_blur", "use_deform_motion", "motion_steps"), U,
          "Act with motion blur only, which the engine does not render (said)"),
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
    Entry("world.light_settings", ("ao_factor",), U,
          "Fast GI's AO factor, which the engine does not use (said); the engine's own AO sky light has its "
          "own settings"),
    Entry("world.light_settings", ("distance",), D,
          "The Ambient Occlusion pass's distance: read when that pass is on (off in the audit's scene; "
          "tests/blender/test_light_passes.py)"),
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
    Entry("material.cycles", ("name",), V, "The property group's name, not a setting"),
    Entry("material.cycles", ("emission_sampling",), C,
          "How Cycles samples emissive meshes: changes noise, not what it converges to"),
    Entry("material.cycles", ("use_bump_map_correction", "volume_sampling", "volume_interpolation",
                              "volume_step_rate"), U,
          "Displacement-as-bump correction and volumes: not rendered"),
    # -- cameras -------------------------------------------------------------------------
    Entry("camera", ("name", "use_fake_user", "use_extra_user", "is_runtime_data", "tag", "passepartout_alpha",
                     "display_size", "show_*", "lens_unit", "composition_guide_color"), V,
          "Name, data-block flags, viewport display and the lens's unit (the lens is the same)"),
    Entry("camera", ("fisheye_polynomial_*", "central_cylindrical_*"), U,
          "The Fisheye Lens Polynomial and Central Cylindrical panoramas are not rendered: the frame fails "
          "with a message naming the type"),
    Entry("camera", ("custom_*",), U, "Custom (OSL script) cameras are not rendered: the frame fails with a message"),
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


def listed(key: str):
    owner, _, prop = key.rpartition(".")
    return next((e for e in ENTRIES if e.owner == owner and any(fnmatch.fnmatchcase(prop, p) for p in e.names)), None)


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
           "are the exceptions, each with its reason; every other one is honoured or said.", ""]
    for kind, title in KINDS.items():
        out += [f"## {title}", "", "| Settings | Why |", "|---|---|"]
        for e in ENTRIES:
            if e.kind == kind:
                names = ", ".join(f"every `{e.owner}` setting" if n == "*" else f"`{e.owner}.{n}`" for n in e.names)
                out.append(f"| {names} | {e.reason} |")
        out.append("")
    return "\n".join(out)


if __name__ == "__main__":
    print(markdown(), end="")
