"""Renders the README's off/on image pairs, one per visibility switch (what `make docs` runs).

    python -m tools.switch_images --output-dir docs/switches

For each switch, the full method with that switch off (A) and on (B), and their
difference, rendered through the add-on's own A/B compare operator (toggle) in real Blender:
- the cube (closed, sharp edges) for wrong-hit elimination, far phase and near phase (with
  flat shading for the near phase: it moves the surface point, which interpolated normals
  do not show, while the chosen splat's own normal does);
- Suzanne's surface (as in the demo) for normal interpolation.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

from tools import dev_extension

BUILD = dev_extension.REPO_ROOT / "build" / "switch_images"
SWITCHES = {  # property -> (scene, what to look at)
    "use_wrong_hit_elimination": "cube",
    "use_far_phase": "cube",
    "use_near_phase": "cube",
    "use_normal_interpolation": "suzanne",
}


def colour(bpy, obj, rgba) -> None:
    """A material of that base colour (what the compare's headlight shades), linked to the
    object: Mesh to Points drops the mesh's own materials."""
    material = bpy.data.materials.new("Colour")
    material.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = rgba
    obj.data.materials.append(None)
    obj.material_slots[0].link = "OBJECT"
    obj.material_slots[0].material = material


def cube_scene(bpy, ply, geometry):
    p, n = geometry.cube_cloud(24)
    path = BUILD / "cube.ply"
    ply.write_ply(str(path), p, n)
    bpy.ops.splat_tracer.import_cloud(filepath=str(path))
    colour(bpy, bpy.context.active_object, (0.85, 0.6, 0.35, 1.0))
    return (3.0, -4.6, 3.4), (math.radians(55), 0.0, math.radians(33)), 50


def suzanne_scene(bpy, ply, demo):
    positions, normals = demo.suzanne_cloud(bpy, 2)
    path = BUILD / "suzanne.ply"
    ply.write_ply(str(path), positions, normals)
    bpy.ops.splat_tracer.import_cloud(filepath=str(path))
    colour(bpy, bpy.context.active_object, (0.8, 0.45, 0.2, 1.0))
    return (2.2, -5.2, 1.4), (math.radians(77), 0.0, math.radians(23)), 55


def main(argv=None) -> int:
    args, bpy = dev_extension.start_docs_tool(BUILD, __doc__, dev_extension.REPO_ROOT / "docs" / "switches", argv)
    from tools import demo
    from tests.support import geometry
    from splat_tracer.pointcloud.readers import ply

    out_root = Path(args.output_dir).resolve()
    for switch, scene_name in SWITCHES.items():
        bpy.ops.wm.read_homefile(use_empty=True)
        scene = bpy.context.scene
        scene.render.engine = "SPLAT_TRACER"
        scene.render.resolution_x, scene.render.resolution_y = 320, 240
        scene.view_settings.view_transform = "Standard"
        scene.world = bpy.data.worlds.new("World")
        scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.03, 0.035, 0.045, 1.0)
        location, rotation, lens = (cube_scene(bpy, ply, geometry) if scene_name == "cube"
                                    else suzanne_scene(bpy, ply, demo))
        cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
        scene.collection.objects.link(cam)
        cam.location, cam.rotation_euler, cam.data.lens = location, rotation, lens
        scene.camera = cam
        settings = scene.splat_tracer
        settings.method = "FULL"
        if switch == "use_near_phase":
            settings.use_normal_interpolation = False
        bpy.ops.splat_tracer.compare(toggle=switch, directory=str(out_root / switch))
    print(f"switch_images: written to {out_root}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
