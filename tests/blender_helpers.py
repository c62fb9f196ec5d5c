"""Building scenes and reading renders back in real bpy."""
from __future__ import annotations

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
    import OpenEXR

    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = width, height, percentage
    layer = scene.view_layers[0]
    layer.use_pass_z = layer.use_pass_normal = passes
    r.image_settings.media_type = "MULTI_LAYER_IMAGE"
    r.image_settings.file_format = "OPEN_EXR_MULTILAYER"
    r.image_settings.color_depth = "32"
    r.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    exr = OpenEXR.File(str(path), separate_channels=True)
    channels = {}
    for part in exr.parts:
        channels.update(part.channels)
    prefix = f"{layer.name}."

    def stack(pass_name, letters):
        return np.stack([channels[f"{prefix}{pass_name}.{c}"].pixels for c in letters], axis=-1)

    out = {"rgba": stack("Combined", "RGBA")}
    if passes:
        out["depth"] = channels[f"{prefix}Depth.Z"].pixels
        out["normal"] = stack("Normal", "XYZ")
    return out


def extension_module(name: str):
    """A module of the enabled extension (e.g. 'session'), as Blender loaded it: the
    extension's package is bl_ext.<repo>.<id>, not the source tree's `splat_tracer`."""
    import sys

    for mod_name, module in sys.modules.items():
        if mod_name.startswith("bl_ext.") and mod_name.endswith(f".splat_tracer.{name}"):
            return module
    raise LookupError(f"the extension's module '{name}' is not loaded")
