"""Renders the user guide's composite: a scan put into a photograph with its shadow, with
Splat Tracer and with Cycles, through Blender's compositor.

    python -m tools.composite_images --output docs/composite.png --cycles docs/composite_cycles.png

What an artist does with a photograph and an HDRI shot at the same place, with both taken
from Blender itself (no file outside the repository is needed): the HDRI is one of the CC0
Poly Haven HDRIs that ship with Blender (datafiles/studiolights/world, "city" by default:
Portland's landing pad, a sun 48 degrees up), and the "photograph" is that HDRI seen through
the render's camera -- a Cycles render of the world alone, made once and given to both
engines, as a plate is given.

The scene: the HDRI as the World (Environment Texture) lights the scan -- Suzanne's points, as
in tools/demo.py -- standing on a plane marked Object > Visibility > Shadow Catcher, with
Film > Transparent on. The compositor (scene.compositing_node_group) lays the render over the
photograph with Alpha Over; each engine renders and composites the same scene with the same
samples, and the times printed are those of bpy.ops.render.render (render and compositing).
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from tools import dev_extension
from tools.demo import add_camera, equal_samples, import_cloud, principled, render, suzanne_cloud

BUILD = dev_extension.REPO_ROOT / "build" / "composite"
HDRIS = ("city", "courtyard", "forest", "interior", "night", "studio", "sunrise", "sunset")


def hdri_path(bpy, name: str) -> Path:
    """One of the HDRIs Blender ships for its viewport's studio lights (CC0, Poly Haven;
    1024 x 512, see license.txt beside them)."""
    return Path(bpy.utils.system_resource("DATAFILES", path="studiolights/world")) / f"{name}.exr"


def hdri_world(bpy, scene, path: Path) -> None:
    scene.world = bpy.data.worlds.new("HDRI")
    tree = scene.world.node_tree
    texture = tree.nodes.new("ShaderNodeTexEnvironment")
    texture.image = bpy.data.images.load(str(path))
    tree.links.new(texture.outputs["Color"], tree.nodes["Background"].inputs["Color"])


def clay_scan(bpy, build: Path, levels: int):
    """Suzanne's points in clay, named "Scan", standing on the ground (z = 0) and facing a
    camera on -Y: the scan of this tool and of tools/demo_hdri.py."""
    positions, normals = suzanne_cloud(bpy, levels)
    clay = principled(bpy, "Clay", **{"Base Color": (0.5, 0.26, 0.12, 1), "Roughness": 0.45})
    scan = import_cloud(bpy, build, "Scan", positions, normals, clay)
    scan.location = (0.0, 0.0, 0.82)  # Suzanne (2 m) sits on the ground
    scan.rotation_euler = (0.0, 0.0, math.radians(-10))
    return scan


def build_scene(bpy, hdri: Path, levels: int, width: int, height: int):
    """The scan on its catcher floor under the HDRI; returns (scene, scan, floor)."""
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scan = clay_scan(bpy, BUILD, levels)

    bpy.ops.mesh.primitive_plane_add(size=40.0)
    floor = bpy.context.active_object
    floor.name = "Catcher"
    floor.data.materials.append(principled(bpy, "Ground", **{"Base Color": (0.5, 0.5, 0.5, 1), "Roughness": 0.8}))
    floor.is_shadow_catcher = True

    hdri_world(bpy, scene, hdri)
    # At eye height (the HDRI's own camera stood about there), looking a little down; the
    # city HDRI's sun then shines from behind the camera's right.
    add_camera(bpy, scene, (0.9, -8.0, 1.7), (84, 0, 6), 30, width, height)
    return scene, scan, floor


def render_plate(bpy, scene, hidden, samples: int, output: Path) -> Path:
    """The "photograph": the world alone through the camera, an opaque float EXR."""
    for obj in hidden:
        obj.hide_render = True
    r = scene.render
    r.engine, r.film_transparent, r.use_compositing = "CYCLES", False, False
    scene.cycles.samples = samples
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_depth = "32"
    r.filepath = str(output)
    bpy.ops.render.render(write_still=True)
    for obj in hidden:
        obj.hide_render = False
    return output


def alpha_over_compositor(bpy, scene, plate: Path):
    """Render Layers' Image (premultiplied, alpha from Film > Transparent) over the plate
    with Alpha Over, into the node group's output (Blender 5's compositor)."""
    tree = bpy.data.node_groups.new("Composite Over Photograph", "CompositorNodeTree")
    tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
    layers = tree.nodes.new("CompositorNodeRLayers")
    photo = tree.nodes.new("CompositorNodeImage")
    photo.image = bpy.data.images.load(str(plate))
    over = tree.nodes.new("CompositorNodeAlphaOver")
    out = tree.nodes.new("NodeGroupOutput")
    tree.links.new(photo.outputs["Image"], over.inputs["Background"])
    tree.links.new(layers.outputs["Image"], over.inputs["Foreground"])
    tree.links.new(over.outputs["Image"], out.inputs[0])
    scene.compositing_node_group = tree
    scene.render.use_compositing = True
    scene.render.film_transparent = True
    return tree


def start_hdri_tool(build: Path, description: str, output: str, argv=None):
    """The start of this tool and of tools/demo_hdri.py: their arguments (the same scene
    options), bpy with throwaway user directories under `build`, and the extension enabled
    from source. Returns (args, bpy)."""
    ap = argparse.ArgumentParser(description=description, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--output", default=output, help=f"Splat Tracer's image (PNG, default: {output})")
    ap.add_argument("--cycles", default=None, help="also render the same with Cycles to this PNG")
    ap.add_argument("--width", type=int, default=400)
    ap.add_argument("--height", type=int, default=300)
    ap.add_argument("--samples", type=int, default=32, help="samples per pixel, for both engines")
    ap.add_argument("--levels", type=int, default=3, help="subdivision levels of Suzanne (3: 31,500 points)")
    ap.add_argument("--hdri", default="city", choices=HDRIS, help="which of Blender's HDRIs (default: city)")
    args = ap.parse_args(argv)

    build.mkdir(parents=True, exist_ok=True)
    dev_extension.isolate_user_dirs(str(build / "blender_user"))
    import bpy

    dev_extension.enable_from_source(build)
    return args, bpy


def render_both(bpy, scene, args, tool: str, what: str) -> None:
    """Renders with Splat Tracer to args.output and, given args.cycles, with Cycles there, and
    prints each time: the end of this tool and of tools/demo_hdri.py."""
    seconds = render(bpy, scene, "SPLAT_TRACER", Path(args.output).resolve())
    print(f"{tool}: {what}, {args.samples} samples, {args.width}x{args.height}: Splat Tracer {seconds:.2f} s "
          f"-> {args.output}")
    if args.cycles:
        cycles_seconds = render(bpy, scene, "CYCLES", Path(args.cycles).resolve())
        print(f"{tool}: Cycles (the cloud as spheres), {args.samples} samples: {cycles_seconds:.2f} s -> "
              f"{args.cycles}")


def main(argv=None) -> int:
    args, bpy = start_hdri_tool(BUILD, __doc__, "composite.png", argv)
    scene, scan, floor = build_scene(bpy, hdri_path(bpy, args.hdri), args.levels, args.width, args.height)
    scene.splat_tracer.samples = args.samples
    equal_samples(scene, args.samples)
    plate = render_plate(bpy, scene, (scan, floor), args.samples, BUILD / f"plate_{args.hdri}.exr")
    alpha_over_compositor(bpy, scene, plate)
    render_both(bpy, scene, args, "composite",
                f"{len(scan.data.vertices):,} splats on a shadow catcher under Blender's '{args.hdri}' HDRI")
    return 0


if __name__ == "__main__":
    sys.exit(main())
