"""Renders the demo: a scan on a floor, lit by a lamp, beside a mirror and a glass sphere,
through the real add-on and Blender's render pipeline.

    python -m tools.demo --output demo.png              (what `make demo` runs)
    python -m tools.demo --output demo.png --cycles docs/demo_cycles.png
                                                        (also renders the same scene with Cycles)

Everything comes from Blender itself (no file outside the repository is needed): the "scan"
is the vertices of Suzanne subdivided three times with their smooth normals, written to a
PLY file and imported with the add-on's importer (radii from the k-NN spacing); the two
spheres are clouds of evenly spread points; the floor is a checkered mesh. A sun with a
soft angle casts the shadows, and the world's sky colour lights the scene too.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from tools import dev_extension

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


def sphere_cloud(n: int, radius: float, centre):
    """n evenly spread points on a sphere (Fibonacci lattice) with their exact normals."""
    import numpy as np

    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5 ** 0.5) * i
    normals = np.column_stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)])
    return normals * radius + np.asarray(centre), normals


def principled(bpy, name: str, **inputs):
    material = bpy.data.materials.new(name)
    node = material.node_tree.nodes["Principled BSDF"]
    for key, value in inputs.items():
        node.inputs[key].default_value = value
    return material


def checker_floor(bpy, size: float, tiles: int):
    """A square floor of tiles x tiles quads alternating between two materials."""
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=tiles, y_subdivisions=tiles, size=size)
    floor = bpy.context.active_object
    floor.name = "Floor"
    floor.data.materials.append(principled(bpy, "Tile Light", **{"Base Color": (0.8, 0.8, 0.8, 1), "Roughness": 0.6}))
    floor.data.materials.append(principled(bpy, "Tile Dark", **{"Base Color": (0.08, 0.1, 0.14, 1), "Roughness": 0.6}))
    step = size / tiles
    for poly in floor.data.polygons:
        c = poly.center
        poly.material_index = (int((c.x + size / 2) // step) + int((c.y + size / 2) // step)) % 2
    return floor


def import_cloud(bpy, build: Path, name: str, positions, normals, material):
    """Writes the points to a PLY file in `build`, imports it with the add-on's importer and
    gives the object `material`. Linked to the object, not the mesh: Geometry Nodes' Mesh to
    Points drops the mesh's materials, and Cycles must see the same material as Splat Tracer."""
    from splat_tracer.pointcloud.readers import ply

    path = build / f"{name.lower().replace(' ', '_')}.ply"
    ply.write_ply(str(path), positions, normals)
    bpy.ops.splat_tracer.import_cloud(filepath=str(path))
    obj = bpy.context.active_object
    obj.name = name
    obj.data.materials.append(None)
    obj.material_slots[0].link = "OBJECT"
    obj.material_slots[0].material = material
    return obj


def sun_and_sky(bpy, scene) -> None:
    """The demo's light: a sun with a soft angle for the shadows and a blue sky colour."""
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy = 3.0
    sun.data.angle = math.radians(4.0)  # a soft shadow edge
    sun.rotation_euler = (math.radians(40), math.radians(-15), math.radians(30))
    scene.collection.objects.link(sun)
    scene.world = bpy.data.worlds.new("World")
    background = scene.world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (0.35, 0.45, 0.6, 1.0)
    background.inputs["Strength"].default_value = 0.6


def add_camera(bpy, scene, location, rotation_degrees, lens: float, width: int, height: int):
    """The scene's camera (rotation in degrees, XYZ Euler) and a width x height PNG output
    with the Standard view transform: the radiance as computed, the same for both engines."""
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    cam.location = location
    cam.rotation_euler = tuple(math.radians(a) for a in rotation_degrees)
    cam.data.lens = lens
    scene.camera = cam
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = width, height, 100
    r.image_settings.file_format = "PNG"
    scene.view_settings.view_transform = "Standard"
    return cam


def build_scene(bpy, levels: int, width: int, height: int):
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    positions, normals = suzanne_cloud(bpy, levels)
    clouds = [("Suzanne", positions, normals)]
    clouds.append(("Mirror Ball", *sphere_cloud(20_000, 0.7, (1.9, 0.6, 0.7))))
    clouds.append(("Glass Ball", *sphere_cloud(20_000, 0.55, (-1.7, -0.6, 0.55))))
    materials = {
        "Suzanne": principled(bpy, "Clay", **{"Base Color": (0.8, 0.42, 0.2, 1), "Roughness": 0.45}),
        "Mirror Ball": principled(bpy, "Mirror", **{"Base Color": (0.95, 0.95, 0.95, 1), "Metallic": 1.0,
                                                    "Roughness": 0.0}),
        "Glass Ball": principled(bpy, "Glass", **{"Base Color": (1, 1, 1, 1), "Transmission Weight": 1.0,
                                                  "Roughness": 0.0, "IOR": 1.45}),
    }
    for name, pos, nrm in clouds:
        import_cloud(bpy, BUILD, name, pos, nrm, materials[name])
    bpy.data.objects["Suzanne"].location = (0.0, 0.0, 1.0)
    checker_floor(bpy, 12.0, 12)

    sun_and_sky(bpy, scene)
    add_camera(bpy, scene, (0.3, -7.8, 2.9), (74, 0, 2), 40, width, height)
    scene.cycles.diffuse_bounces = 1   # the same light paths for both engines
    scene.cycles.glossy_bounces = 4
    scene.cycles.transmission_bounces = 8
    return scene, sum(len(c[1]) for c in clouds)


def equal_samples(scene, samples: int) -> None:
    """Cycles at `samples` samples per pixel, denoising and adaptive sampling off, on the CPU:
    what the tools' side-by-side images and times compare, the same work for both engines."""
    c = scene.cycles
    c.samples = c.preview_samples = samples
    c.use_denoising, c.use_adaptive_sampling, c.device = False, False, "CPU"


def render(bpy, scene, engine: str, output: Path) -> float:
    """Renders the frame with `engine` to the 8-bit PNG `output`; returns the seconds of
    bpy.ops.render.render (compositing included). The format is set here: a render before
    (tools/composite_images.py's plate) may have left it at a float EXR."""
    scene.render.engine = engine
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_depth = "8"
    scene.render.filepath = str(output)
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    seconds = time.perf_counter() - t0
    if not output.is_file():
        raise SystemExit(f"{engine}: no image was written to {output}")
    return seconds


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--output", default="demo.png", help="PNG to write (default: demo.png)")
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--samples", type=int, default=16, help="samples per pixel, for both engines")
    ap.add_argument("--levels", type=int, default=3, help="subdivision levels of Suzanne (3: 31,500 points)")
    ap.add_argument("--cycles", default=None, help="also render the scene with Cycles to this PNG")
    args = ap.parse_args(argv)

    BUILD.mkdir(parents=True, exist_ok=True)
    dev_extension.isolate_user_dirs(str(BUILD / "blender_user"))
    import bpy

    dev_extension.enable_from_source(BUILD)
    scene, n_splats = build_scene(bpy, args.levels, args.width, args.height)
    scene.cycles.samples = scene.cycles.preview_samples = args.samples
    seconds = render(bpy, scene, "SPLAT_TRACER", Path(args.output).resolve())
    print(f"demo: {n_splats:,} splats and a {len(bpy.data.objects['Floor'].data.polygons)}-quad floor, "
          f"{args.samples} samples, {args.width}x{args.height}: Splat Tracer {seconds:.2f} s -> {args.output}")
    if args.cycles:
        scene.cycles.samples = args.samples
        scene.cycles.use_denoising = False
        scene.cycles.use_adaptive_sampling = False
        scene.cycles.device = "CPU"
        cycles_seconds = render(bpy, scene, "CYCLES", Path(args.cycles).resolve())
        print(f"demo: Cycles (the clouds as spheres), {args.samples} samples: {cycles_seconds:.2f} s -> "
              f"{args.cycles}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
