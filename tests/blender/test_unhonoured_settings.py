"""Never silently (issues 25 and 26): settings the engine does not honour."""
from __future__ import annotations

import math

import numpy as np

from blender_helpers import add_camera, read_exr

W, H = 32, 24


def test_every_view_of_a_stereo_render_gets_the_image(blender, empty_scene, tmp_path):
    """A stereo render writes the one image into both eyes (before: the right eye was black)."""
    bpy = blender
    scene = empty_scene
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    add_camera(bpy, scene, (0, -5, 0), (math.radians(90), 0, 0))
    scene.splat_tracer.lighting = "HEADLIGHT"
    scene.render.resolution_x, scene.render.resolution_y = W, H
    scene.cycles.samples = 1
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
