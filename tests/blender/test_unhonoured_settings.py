"""Never silently (issues 25 and 26): each scene, view-layer or camera setting the engine does not
honour is named once in the render report, with what the engine did instead
(export/settings.py); with the setting at its default, no such line.

Each case renders a small scene twice through real bpy: as it is (no line), then with the one
setting changed (exactly one line naming it).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from blender_helpers import add_camera, extension_module, read_exr

W, H = 32, 24
LAYER = "view layer 'ViewLayer'"


def settings_module():
    return extension_module("blender.export.settings")


def render(bpy) -> list:
    """Renders the scene (no file) and returns the frame's report lines."""
    bpy.ops.render.render()
    return extension_module("blender.session").HISTORY[-1]["report"]


def lines_with(lines: list, *parts: str) -> list:
    return [line for line in lines if all(p in line for p in parts)]


@pytest.fixture
def small_scene(blender, empty_scene):
    """A mesh cube before the camera, lit by the headlight, 32 x 24 pixels, 1 sample; Cycles'
    Denoise (on by default) off, so that a case's line is the only one."""
    bpy = blender
    scene = empty_scene
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    add_camera(bpy, scene, (0, -5, 0), (math.radians(90), 0, 0))
    scene.splat_tracer.lighting = "HEADLIGHT"
    scene.render.resolution_x, scene.render.resolution_y = W, H
    scene.cycles.samples = 1
    scene.cycles.use_denoising = False
    return scene


def _stereo_panorama(bpy, scene):
    scene.render.use_multiview = True
    scene.camera.data.type = "PANO"
    scene.camera.data.panorama_type = "EQUIRECTANGULAR"
    return ("camera 'Camera': stereo panorama rendered with each eye's camera moved",
            "not Cycles' spherical stereo")


def _light_groups_past_the_bound(bpy, scene):
    # Each group up to the core's bound gets its Combined_<group> pass (test_light_passes.py);
    # the one past it is the one line.
    bound = extension_module("render.shading").MAX_LIGHT_GROUPS
    for i in range(bound + 1):
        scene.view_layers[0].lightgroups.add(name=f"Group{i}")
    lamp = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
    scene.collection.objects.link(lamp)
    lamp.lightgroup = f"Group{bound}"
    return (f"{LAYER}: the light group 'Group{bound}' pass is not written", f"only the first {bound}")


def _vector_deformation(bpy, scene):
    # The cube deformed by a modifier: its points' own motion between frames is not captured.
    scene.view_layers[0].use_pass_vector = True
    bpy.data.objects["Cube"].modifiers.new("Bevel", "BEVEL")
    return ("Vector pass: deformation is not captured ('Cube')", "move as wholes")


def _optix(bpy, scene):
    # Set as stored (OptiX is 2 in Cycles' items), as a file saved on a machine with an NVIDIA
    # GPU holds it: here the enum has no OptiX item to set it through.
    scene.cycles.use_denoising = True
    system = getattr(scene.cycles, "bl_system_properties_get", None)
    (system() if system is not None else scene.cycles)["denoiser"] = 2
    return ("Denoiser OptiX is Cycles' GPU denoiser: the image is denoised by OpenImageDenoise instead",)


def _film_exposure(bpy, scene):
    scene.cycles.film_exposure = 2.0
    return ("Cycles' Film > Exposure (2) is not applied", "rendered at 1")


def _caustics(bpy, scene):
    scene.cycles.caustics_refractive = False
    return ("Cycles' Caustics > Reflective/Refractive off is not honoured",)


def _layer_samples(bpy, scene):
    scene.view_layers[0].samples = 8
    return (f"{LAYER}: its Samples override (8) is not used", "the scene's 1 samples")


def _layer_filter(bpy, scene):
    scene.view_layers[0].use_sky = False
    return (f"{LAYER}: Filter > Environment off is not honoured",)


def _lamp_influence(bpy, scene):
    lamp = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
    scene.collection.objects.link(lamp)
    lamp.data.diffuse_factor = 0.5
    return ("light 'Lamp': its Diffuse influence is ignored (rendered as 1)",)


CASES = {"stereo panorama": _stereo_panorama,
         "light groups past the bound": _light_groups_past_the_bound, "vector deformation": _vector_deformation,
         "OptiX denoiser": _optix, "film exposure": _film_exposure, "caustics": _caustics,
         "view layer samples": _layer_samples, "view layer filter": _layer_filter, "lamp influence": _lamp_influence}


@pytest.mark.parametrize("case", sorted(CASES))
def test_a_scene_setting_not_honoured_is_said_once(blender, small_scene, case):
    bpy = blender
    before = render(bpy)
    parts = CASES[case](bpy, small_scene)
    assert not lines_with(before, parts[0]), before
    after = render(bpy)
    assert len(lines_with(after, *parts)) == 1, (parts, after)


def test_a_shader_aov_is_written_not_said(blender, small_scene):
    """Shader AOVs are honoured (tests/blender/test_shader_aov.py): adding one says nothing."""
    small_scene.view_layers[0].aovs.add().name = "Wetness"
    assert not lines_with(render(blender), "AOV"), "a shader AOV is written: nothing to say"


def test_vector_of_a_still_rigid_scene_says_nothing(blender, small_scene):
    """The Vector pass is computed with motion blur off (test_vector_pass.py) and is Cycles'
    zero with it on: for a rigid cube, nothing is said either way."""
    bpy = blender
    small_scene.view_layers[0].use_pass_vector = True
    for blur in (True, False):
        small_scene.render.use_motion_blur = blur
        assert not lines_with(render(bpy), "Vector"), blur


def _pass_switches():
    return [(owner, prop, label) for owner, prop, label in settings_module().UNWRITTEN_PASSES]


def test_every_unwritten_pass_is_said_once(blender, small_scene):
    """One render per pass switch of the table, each alone: its line, and only its line."""
    bpy = blender
    layer = small_scene.view_layers[0]
    assert lines_with(render(bpy), "pass is not written") == []
    for owner, prop, label in _pass_switches():
        group = getattr(layer, owner) if owner else layer
        setattr(group, prop, True)
        said = lines_with(render(bpy), "pass is not written")
        setattr(group, prop, False)
        assert said == [f"{LAYER}: the {label} pass is not written"], (prop, said)


def test_the_pass_tables_cover_every_pass_switch_of_blender(blender):
    """Every pass switch in Blender's RNA (the view layer's and Cycles' on it) is written by
    the engine (engine.py's table), said as not written (export/settings.py's), or not a pass
    -- so a pass a new Blender adds fails here instead of going unsaid."""
    bpy = blender
    engine = extension_module("blender.engine")
    # Accurate Mode: a mode of the Cryptomatte passes, no pass of its own -- and one neither
    # Cycles nor 5.0's panels use (the engine keeps the pixel's first ids, as Cycles).
    not_passes = {"use_pass_combined",             # always written
                  "use_pass_cryptomatte_accurate"}
    # Denoising Data: the Denoising Normal/Albedo/Depth passes (export/settings.py denoising_passes).
    written = ({prop for prop, *_ in engine._PASSES} | set(engine._CRYPTOMATTE.values())
               | {"cycles.denoising_store_passes"})
    unwritten = {f"{owner}.{prop}" if owner else prop for owner, prop, _ in _pass_switches()}
    assert not written & unwritten
    layer = bpy.context.scene.view_layers[0]
    switches = {p.identifier for p in layer.bl_rna.properties if p.identifier.startswith("use_pass_")}
    switches |= {f"cycles.{p.identifier}" for p in layer.cycles.bl_rna.properties
                 if p.identifier.startswith(("use_pass_", "pass_")) or p.identifier == "denoising_store_passes"}
    assert switches - not_passes == written | unwritten


def test_a_default_scene_says_none_of_it(blender, empty_scene):
    """Blender's default scene and view layer, with Cycles' defaults (Denoise on, which the
    engine applies): nothing unhonoured is said."""
    bpy = blender
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    add_camera(bpy, empty_scene, (0, -5, 0), (math.radians(90), 0, 0))
    empty_scene.render.resolution_x, empty_scene.render.resolution_y = W, H
    empty_scene.cycles.samples = 1
    empty_scene.cycles.use_denoising = True  # Cycles' default (the fixture turns it off)
    lines = render(bpy)
    assert not [line for line in lines if any(k in line for k in ("not rendered", "not applied", "not written"))], lines
    assert "denoised by OpenImageDenoise" in extension_module("blender.session").HISTORY[-1]["sampling"]


def test_every_view_of_a_stereo_render_gets_its_own_image(blender, small_scene, tmp_path):
    """A stereo render writes each eye's own image (before: one image in both; before that,
    the right eye was black). test_stereo.py measures the disparity against Cycles'."""
    bpy = blender
    scene = small_scene
    scene.render.use_multiview = True
    r = scene.render
    r.image_settings.media_type = "MULTI_LAYER_IMAGE"
    r.image_settings.file_format = "OPEN_EXR_MULTILAYER"
    r.image_settings.color_depth = "32"
    r.filepath = str(tmp_path / "stereo.exr")
    bpy.ops.render.render(write_still=True)
    eyes = [read_exr(tmp_path / f"stereo_{side}.exr") for side in "LR"]
    left, right = (np.stack([e[f"ViewLayer.Combined.{c}"].pixels for c in "RGBA"], -1) for e in eyes)
    assert left[..., 3].mean() > 0.1 and right[..., 3].mean() > 0.1  # the cube is in both
    assert not np.array_equal(left, right)


class _Newer:
    """A struct of this bpy with a setting a newer Blender added (the version matrix found
    it; tests/blender/settings_walk.py): `extra` read first, the rest from the struct."""

    def __init__(self, struct, **extra):
        self._struct, self._extra = struct, extra

    def __getattr__(self, name):
        return self._extra[name] if name in self._extra else getattr(self._struct, name)


@pytest.mark.parametrize("scale", [1.0, 0.5])
def test_render_texture_resolution_of_blender_5_2_is_said(blender, small_scene, scale):
    report = extension_module("render.shading").Report()
    cycles = _Newer(small_scene.cycles, texture_resolution_render=scale)
    settings_module()._report_cycles_scene(small_scene, cycles, report)
    said = lines_with(report.lines, "Render Texture Resolution")
    assert said == ([] if scale == 1.0 else ["Cycles' Render Texture Resolution (0.5) is not applied: images are read "
                                              "at their full resolution"]), report.lines


@pytest.mark.parametrize("shadows", [True, False])
def test_world_shadows_off_of_blender_5_2_is_said(blender, small_scene, shadows):
    small_scene.world = blender.data.worlds.new("Sky")
    world = _Newer(small_scene.world, cycles=_Newer(small_scene.world.cycles, use_shadows=shadows))
    report = extension_module("render.shading").Report()
    extension_module("blender.export.shading").world_of(_Newer(small_scene, world=world), report)
    said = lines_with(report.lines, "Shadows off")
    assert said == ([] if shadows else ["world 'Sky': Shadows off is not honoured: the world's light casts "
                                        "shadows"]), report.lines
