"""Renders the README's viewport screenshots (what `make docs` runs):

    python -m tools.viewport_images --output-dir docs/viewport

A headless render of what the Rendered viewport draws, made by the viewport's own code: a
3D view's matrices (a perspective view of Suzanne's surface as splats, lit by a sun) are
turned into the core camera by viewport.camera_from_view, the viewport session renders A
(the General preset) and B (Full) as it does in Blender, and ab.display_buffer composes
what view_draw uploads: A, B, the split wipe and the split wipe with the difference
overlay. Each is saved through the scene's view transform (Standard here), as the viewport's
display transform shows it. Only the GPU upload itself (engine._draw_pixels) is not run.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

from tools import dev_extension

BUILD = dev_extension.REPO_ROOT / "build" / "viewport_images"
WIDTH, HEIGHT = 480, 270   # small PNGs for the README
SPLIT = 0.5


def main(argv=None) -> int:
    args, bpy = dev_extension.start_docs_tool(BUILD, __doc__, dev_extension.REPO_ROOT / "docs" / "viewport", argv)
    import numpy as np
    from tools import switch_images

    addon = sys.modules[dev_extension.ADDON_MODULE + ".splat_tracer.blender.viewport"]
    ab = sys.modules[dev_extension.ADDON_MODULE + ".splat_tracer.render.ab"]
    from splat_tracer.pointcloud.readers import ply
    from tools import demo

    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "SPLAT_TRACER"
    scene.view_settings.view_transform = "Standard"
    scene.world = bpy.data.worlds.new("World")
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.05, 0.06, 0.08, 1.0)
    switch_images.BUILD.mkdir(parents=True, exist_ok=True)
    location, rotation, lens = switch_images.suzanne_scene(bpy, ply, demo)
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy, sun.rotation_euler = 3.0, (math.radians(40), math.radians(-15), math.radians(30))
    scene.collection.objects.link(sun)
    scene.cycles.samples = scene.cycles.preview_samples = 8
    props = scene.splat_tracer.ab
    props.mode = "SPLIT"           # A: the General preset, B: the scene's (Full)
    props.a.method = "GENERAL"

    # The 3D view: a camera object only supplies the matrices a perspective RegionView3D has
    # (its projection for the region, the inverse of its world matrix); it is not the scene camera.
    view_obj = bpy.data.objects.new("View", bpy.data.cameras.new("View"))
    scene.collection.objects.link(view_obj)
    view_obj.location, view_obj.rotation_euler, view_obj.data.lens = location, rotation, lens * 1.15
    scene.camera = view_obj  # the session's origin comes from the scene camera, as in Blender
    bpy.context.view_layer.update()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    window = view_obj.calc_matrix_camera(depsgraph, x=WIDTH, y=HEIGHT)
    view = addon.View.of(window, np.linalg.inv(np.array(view_obj.matrix_world, np.float64)), WIDTH, HEIGHT)

    session = addon.ViewportSession()
    session.set_view(view)
    session.update(depsgraph)
    session.refine()
    images, _ = session.snapshot()
    a, b = images["A"].pixels, images["B"].pixels
    shots = {"a": ab.display_buffer("A", a.shape, a=a, b=b),
             "b": ab.display_buffer("B", a.shape, a=a, b=b),
             "split": ab.display_buffer("SPLIT", a.shape, a=a, b=b, split=SPLIT),
             "split_difference": ab.display_buffer("SPLIT", a.shape, a=a, b=b, split=SPLIT, overlay=True)}
    session.close()

    out = Path(args.output_dir).resolve()
    out.mkdir(parents=True, exist_ok=True)
    for name, pixels in shots.items():
        image = bpy.data.images.new(name, WIDTH, HEIGHT, alpha=True, float_buffer=True)
        image.pixels.foreach_set(np.ascontiguousarray(pixels[::-1], np.float32).ravel())
        image.save_render(str(out / f"viewport_{name}.png"), scene=scene)
    print(f"viewport_images: {len(shots)} images ({WIDTH}x{HEIGHT}, {images['B'].samples} samples) written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
