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


def _motion_blur(bpy, scene):
    scene.frame_set(7)
    scene.render.use_motion_blur = True
    return ("Motion Blur is not rendered", "rendered sharp at frame 7's time", "shutter of 0.5 frames")


def _stereo(bpy, scene):
    scene.render.use_multiview = True
    return ("Stereoscopy is not rendered", "every view ('left', 'right') gets the same image")


def _multiview(bpy, scene):
    scene.render.use_multiview = True
    scene.render.views_format = "MULTIVIEW"
    scene.render.views["right"].use = False
    view = scene.render.views.new("top")
    view.use = True
    return ("Stereoscopy is not rendered", "every view ('left', 'top') gets the same image")


def _denoising(bpy, scene):
    scene.cycles.use_denoising = True
    return ("Cycles' Denoise is not applied", "The compositor's Denoise node", "Normal and Diffuse Color passes")


def _light_group(bpy, scene):
    scene.view_layers[0].lightgroups.add(name="Key")
    # A lamp in the group lights the image as usual: the group's missing pass is the one line.
    lamp = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
    scene.collection.objects.link(lamp)
    lamp.lightgroup = "Key"
    return (f"{LAYER}: the light group 'Key' pass is not written",)


CASES = {"motion blur": _motion_blur, "stereo 3D": _stereo, "multi-view": _multiview, "denoising": _denoising,
         "light group": _light_group}


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
    not_passes = {"use_pass_combined",             # always written
                  "use_pass_cryptomatte_accurate"}  # a mode of the Cryptomatte passes, no pass of its own
    written = {prop for prop, *_ in engine._PASSES}
    unwritten = {f"{owner}.{prop}" if owner else prop for owner, prop, _ in _pass_switches()}
    assert not written & unwritten
    layer = bpy.context.scene.view_layers[0]
    switches = {p.identifier for p in layer.bl_rna.properties if p.identifier.startswith("use_pass_")}
    switches |= {f"cycles.{p.identifier}" for p in layer.cycles.bl_rna.properties
                 if p.identifier.startswith(("use_pass_", "pass_")) or p.identifier == "denoising_store_passes"}
    assert switches - not_passes == written | unwritten


def test_a_default_scene_says_none_of_it(blender, empty_scene):
    """Blender's default scene and view layer, with Cycles' defaults: only Denoise (on by default
    in Cycles, and the engine does not denoise) is said."""
    bpy = blender
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    add_camera(bpy, empty_scene, (0, -5, 0), (math.radians(90), 0, 0))
    empty_scene.render.resolution_x, empty_scene.render.resolution_y = W, H
    empty_scene.cycles.samples = 1
    lines = render(bpy)
    unhonoured = [line for line in lines if any(k in line for k in ("not rendered", "not applied", "not written"))]
    assert len(unhonoured) == 1 and unhonoured[0].startswith("Cycles' Denoise is not applied"), lines
    empty_scene.view_layers[0].cycles.use_denoising = False  # the view layer's own Denoise switch
    assert not lines_with(render(bpy), "Denoise")


def test_every_view_of_a_stereo_render_gets_the_image(blender, small_scene, tmp_path):
    """A stereo render writes the one image into both eyes (before: the right eye was black)."""
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
    assert left[..., 3].mean() > 0.1  # the cube is there
    np.testing.assert_array_equal(left, right)
