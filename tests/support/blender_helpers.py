"""Building scenes and reading renders back in real bpy."""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np


def add_camera(bpy, scene, location, rotation, **camera_settings):
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    cam.location, cam.rotation_euler = location, rotation
    for key, value in camera_settings.items():
        setattr(cam.data, key, value)
    scene.camera = cam
    bpy.context.view_layer.update()  # so that cam.matrix_world reflects the new transform
    return cam


def render_to_exr(bpy, scene, path: Path, width=320, height=240, percentage=100, passes=True) -> dict:
    """Renders with the Depth and Normal passes and reads the multilayer EXR back.
    Returns {'rgba': (H,W,4), 'depth': (H,W), 'normal': (H,W,3)}, top row first."""
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = width, height, percentage
    layer = scene.view_layers[0]
    layer.use_pass_z = layer.use_pass_normal = passes
    r.image_settings.media_type = "MULTI_LAYER_IMAGE"
    r.image_settings.file_format = "OPEN_EXR_MULTILAYER"
    r.image_settings.color_depth = "32"
    r.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    channels = read_exr(path)
    prefix = f"{layer.name}."

    def stack(pass_name, letters):
        return np.stack([channels[f"{prefix}{pass_name}.{c}"].pixels for c in letters], axis=-1)

    out = {"rgba": stack("Combined", "RGBA")}
    if passes:
        out["depth"] = channels[f"{prefix}Depth.Z"].pixels
        out["normal"] = stack("Normal", "XYZ")
    return out


def read_exr(path) -> dict:
    """The channels of a (multilayer) EXR, by name ('ViewLayer.Depth.Z'), of all its parts."""
    import OpenEXR

    channels = {}
    for part in OpenEXR.File(str(path), separate_channels=True).parts:
        channels.update(part.channels)
    return channels


def extension_module(name: str):
    """A module of the enabled extension (e.g. 'blender.session'), as Blender loaded it: the
    extension's package is bl_ext.<repo>.<id>, not the source tree's `splat_tracer`."""
    import sys

    for mod_name, module in sys.modules.items():
        if mod_name.startswith("bl_ext.") and mod_name.endswith(f".splat_tracer.{name}"):
            return module
    raise LookupError(f"the extension's module '{name}' is not loaded")


# The scene install_and_render.py renders: a unit sphere cloud at the origin, seen from 5
# units by Blender's default camera (50 mm lens on a 36 mm sensor), 160 x 120 pixels, with a
# black world (so the headlight: base colour x |cos|, the default base colour 0.8).
SPHERE_DISTANCE, LENS_MM, SENSOR_MM, WIDTH, HEIGHT, BASE_COLOUR = 5.0, 50.0, 36.0, 160, 120, 0.8


def check_sphere_render(path, new_pass_names: bool) -> None:
    """Fails unless the EXR install_and_render.py wrote shows the sphere as it should be:
    its coverage and nearest depth from the geometry, its colour from the headlight, the
    normal facing the camera, and every pass under the name the Blender version gives it
    (new_pass_names: Blender 5.0+, "Diffuse Color"/"Object Index", else "DiffCol"/"IndexOB")."""
    channels = read_exr(path)
    depth = channels["ViewLayer.Depth.Z"].pixels
    assert depth.shape == (HEIGHT, WIDTH)
    hit = depth < 1e9
    # The silhouette's radius on the image: the tangent cone's half-angle asin(r/d), in
    # pixels of focal length LENS/SENSOR*WIDTH (sensor fit: width). The splats' radii may
    # add a fraction of a pixel at the rim: 0.01 of coverage is ~0.7 pixel of radius.
    focal = LENS_MM / SENSOR_MM * WIDTH
    radius_px = focal * math.tan(math.asin(1.0 / SPHERE_DISTANCE))
    expected = math.pi * radius_px**2 / (WIDTH * HEIGHT)
    assert abs(hit.mean() - expected) < 0.01, (hit.mean(), expected)
    np.testing.assert_allclose(depth[hit].min(), SPHERE_DISTANCE - 1.0, atol=0.02)  # the nearest point
    rgb = np.stack([channels[f"ViewLayer.Combined.{c}"].pixels for c in "RGB"], axis=-1)
    centre = rgb[HEIGHT // 2 - 1:HEIGHT // 2 + 1, WIDTH // 2 - 1:WIDTH // 2 + 1].reshape(-1, 3)
    np.testing.assert_allclose(centre, BASE_COLOUR, atol=0.01)  # facing the headlight: |cos| = 1
    assert np.median(rgb[~hit]) == 0.0  # the black world
    assert (rgb[hit].max(axis=-1) > 0.0).mean() > 0.99  # no black holes on the sphere
    normal = np.stack([channels[f"ViewLayer.Normal.{c}"].pixels for c in "XYZ"], axis=-1)
    np.testing.assert_allclose(normal[HEIGHT // 2, WIDTH // 2], (0.0, -1.0, 0.0), atol=0.05)  # towards the camera
    diffuse, index = ("Diffuse Color", "Object Index") if new_pass_names else ("DiffCol", "IndexOB")
    # The diffuse lobe's albedo: the base colour less what the specular lobe takes (a few %).
    assert 0.7 < channels[f"ViewLayer.{diffuse}.R"].pixels[HEIGHT // 2, WIDTH // 2] <= BASE_COLOUR
    assert f"ViewLayer.{index}.X" in channels, sorted(channels)


def blender_user_env(base: Path) -> dict:
    """The environment of a bpy subprocess with its own empty Blender user directories and
    nothing from this source tree on its path: it can only use what a zip installs."""
    env = dict(os.environ)
    for var in ("BLENDER_USER_CONFIG", "BLENDER_USER_SCRIPTS", "BLENDER_USER_RESOURCES"):
        env[var] = str(base / var.lower())
    env["PYTHONPATH"] = ""
    return env


def check_lit_sphere_render(path) -> None:
    """The second image of install_and_render.py (<name>_lit.exr): the sun lights the
    sphere's left half as the camera sees it, the right half has only the dim world."""
    channels = read_exr(path)
    hit = channels["ViewLayer.Depth.Z"].pixels < 1e9
    grey = sum(channels[f"ViewLayer.Combined.{c}"].pixels for c in "RGB") / 3
    third = WIDTH // 3
    left, right = grey[:, :third][hit[:, :third]], grey[:, -third:][hit[:, -third:]]
    assert left.size and right.size, "the sphere is missing from a side"
    # Lambert with 3 W/m^2 against a 0.05 world: several times brighter, by any measure.
    assert left.mean() > 5 * right.mean() > 0.0, (left.mean(), right.mean())
