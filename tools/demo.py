"""Renders the demo image: Blender's Suzanne as a splat cloud, through the real add-on.

    python tools/demo.py --output demo.png        (what `make demo` runs)

The cloud comes from Blender itself (no file outside the repository is needed): the
vertices of Suzanne subdivided three times, with their smooth vertex normals, are written
to a PLY file, imported with the add-on's importer (radii from the k-NN spacing) and
rendered by the SPLAT_TRACER engine with Blender's camera and render pipeline.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import dev_extension  # noqa: E402

BUILD = dev_extension.REPO_ROOT / "build" / "demo"


def suzanne_cloud(bpy, levels: int):
    import numpy as np

    bpy.ops.mesh.primitive_monkey_add(size=2.0)
    obj = bpy.context.active_object
    mod = obj.modifiers.new("subdivide", "SUBSURF")
    mod.levels = levels
    mesh = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh()
    n = len(mesh.vertices)
    pos, nrm = np.empty(3 * n, np.float32), np.empty(3 * n, np.float32)
    mesh.vertices.foreach_get("co", pos)
    mesh.vertex_normals.foreach_get("vector", nrm)
    obj.to_mesh_clear()
    bpy.data.objects.remove(obj)
    return pos.reshape(-1, 3), nrm.reshape(-1, 3)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--output", default="demo.png", help="PNG to write (default: demo.png)")
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--levels", type=int, default=3, help="subdivision levels of Suzanne (3: 31,500 points)")
    args = ap.parse_args(argv)

    BUILD.mkdir(parents=True, exist_ok=True)
    dev_extension.isolate_user_dirs(str(BUILD / "blender_user"))
    import bpy

    sys.path.insert(0, str(dev_extension.REPO_ROOT))
    from splat_tracer import ply

    dev_extension.enable_from_source(BUILD)
    bpy.ops.wm.read_homefile(use_empty=True)
    positions, normals = suzanne_cloud(bpy, args.levels)
    cloud_path = BUILD / "suzanne.ply"
    ply.write_ply(str(cloud_path), positions, normals)

    scene = bpy.context.scene
    bpy.ops.splat_tracer.import_cloud(filepath=str(cloud_path))
    cloud = bpy.context.active_object
    cloud.color = (0.8, 0.45, 0.2, 1.0)  # the headlight shades the object's colour

    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    cam.location = (2.2, -5.2, 1.4)
    cam.rotation_euler = (math.radians(77), 0.0, math.radians(23))
    cam.data.lens = 55
    scene.camera = cam
    scene.world = bpy.data.worlds.new("World")
    scene.world.color = (0.03, 0.035, 0.045)

    r = scene.render
    r.engine = "SPLAT_TRACER"
    r.resolution_x, r.resolution_y, r.resolution_percentage = args.width, args.height, 100
    r.image_settings.file_format = "PNG"
    scene.view_settings.view_transform = "Standard"  # show the shading as computed
    output = Path(args.output).resolve()
    r.filepath = str(output)
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    seconds = time.perf_counter() - t0
    if not output.is_file():
        print(f"demo: no image was written to {output}", file=sys.stderr)
        return 1
    print(f"demo: {len(positions):,} splats rendered at {args.width}x{args.height} in {seconds:.2f} s -> {output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
