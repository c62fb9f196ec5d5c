"""Renders the second demo: a scan lit by an HDRI on an image-textured floor, beside Cycles.

    python -m tools.demo_hdri --output docs/demo_hdri.png --cycles docs/demo_hdri_cycles.png
                                                        (what `make demo-hdri` runs)

Everything comes from Blender itself or is generated here (no file outside the repository is
needed): the scan is Suzanne's points, as in tools/demo.py; the world is one of the CC0 Poly
Haven HDRIs that ship with Blender (datafiles/studiolights/world, "city" by default, as in
tools/composite_images.py: a sun 48 degrees up), an Environment Texture lighting the scene
and seen behind it; the floor is a UV-mapped plane whose Base Color is an Image Texture of
stone tiles, a 256 x 256 PNG generated here, saved to build/demo_hdri/ and packed into the
file, repeated across the floor by a Mapping node. Both engines render the same scene with
the same samples; the times printed are those of bpy.ops.render.render.
"""
from __future__ import annotations

import sys
from pathlib import Path

from tools import dev_extension
from tools.composite_images import clay_scan, hdri_path, hdri_world, render_both, start_hdri_tool
from tools.demo import add_camera, equal_samples, principled

BUILD = dev_extension.REPO_ROOT / "build" / "demo_hdri"
# Floor textures the benchmark compares (benchmarks/frame_time.py); the demo uses "image".
FLOOR_TEXTURES = ("constant", "checker", "image", "noise_ramp")


def tile_image(bpy, path: Path, size: int = 256):
    """A size x size PNG of 4 x 4 stone tiles with grout, each tile its own shade with a
    little grain, saved to `path`, loaded back and packed (the .blend would carry it)."""
    import numpy as np

    rng = np.random.default_rng(7)  # fixed: the same image every run
    tiles = 4
    step = size // tiles
    y, x = np.mgrid[0:size, 0:size]
    tile_index = (y // step) * tiles + x // step
    shades = rng.uniform(0.75, 1.1, tiles * tiles)[tile_index]
    base = np.array([0.62, 0.5, 0.38])  # warm sandstone, sRGB
    rgb = base * shades[..., None] + rng.normal(0, 0.025, (size, size, 1))
    grout = (x % step < 3) | (y % step < 3)  # 3-pixel joints, dark grey
    rgb[grout] = (0.18, 0.17, 0.16)
    rgba = np.concatenate([np.clip(rgb, 0, 1), np.ones((size, size, 1))], axis=-1).astype(np.float32)
    image = bpy.data.images.new("Tiles", size, size)
    image.pixels.foreach_set(rgba.ravel())
    image.filepath_raw, image.file_format = str(path), "PNG"
    image.save()
    bpy.data.images.remove(image)
    loaded = bpy.data.images.load(str(path))
    loaded.pack()
    return loaded


def floor_material(bpy, kind: str, repeat: float = 6.0):
    """The floor's material: a constant colour, or its Base Color from a UV Checker, the
    tile image, or Noise (detail 4) -> Color Ramp; the textures repeat `repeat` times."""
    material = principled(bpy, f"Floor {kind}", **{"Base Color": (0.5, 0.42, 0.33, 1), "Roughness": 0.7})
    if kind == "constant":
        return material
    nodes, links = material.node_tree.nodes, material.node_tree.links
    shader = nodes["Principled BSDF"]
    coords, mapping = nodes.new("ShaderNodeTexCoord"), nodes.new("ShaderNodeMapping")
    mapping.inputs["Scale"].default_value = (repeat, repeat, 1)
    links.new(coords.outputs["UV"], mapping.inputs["Vector"])
    if kind == "checker":
        tex = nodes.new("ShaderNodeTexChecker")
        tex.inputs["Scale"].default_value = 2.0
        tex.inputs["Color1"].default_value = (0.6, 0.5, 0.38, 1)
        tex.inputs["Color2"].default_value = (0.2, 0.18, 0.16, 1)
        out = tex.outputs["Color"]
    elif kind == "image":
        tex = nodes.new("ShaderNodeTexImage")
        tex.image = tile_image(bpy, BUILD / "tiles.png")
        out = tex.outputs["Color"]
    elif kind == "noise_ramp":
        tex = nodes.new("ShaderNodeTexNoise")
        tex.inputs["Scale"].default_value = 3.0
        tex.inputs["Detail"].default_value = 4.0
        ramp = nodes.new("ShaderNodeValToRGB")
        ramp.color_ramp.elements[0].color = (0.2, 0.18, 0.16, 1)
        ramp.color_ramp.elements[1].color = (0.6, 0.5, 0.38, 1)
        links.new(tex.outputs["Fac"], ramp.inputs["Fac"])
        out = ramp.outputs["Color"]
    else:
        raise ValueError(f"unknown floor texture {kind!r}")
    links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
    links.new(out, shader.inputs["Base Color"])
    return material


def build_scene(bpy, hdri: Path, levels: int, width: int, height: int):
    """The scan on its textured floor under the HDRI; returns (scene, scan, floor)."""
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scan = clay_scan(bpy, BUILD, levels)

    bpy.ops.mesh.primitive_plane_add(size=16.0)  # UV-mapped 0..1 across it
    floor = bpy.context.active_object
    floor.name = "Floor"
    floor.data.materials.append(floor_material(bpy, "image"))

    hdri_world(bpy, scene, hdri)
    # The composite's view (tools/composite_images.py), a little higher to show the floor;
    # the city HDRI's sun then shines from behind the camera's right.
    add_camera(bpy, scene, (0.9, -8.0, 2.6), (78, 0, 6), 32, width, height)
    scene.cycles.diffuse_bounces = 1  # the same light paths for both engines
    return scene, scan, floor


def main(argv=None) -> int:
    args, bpy = start_hdri_tool(BUILD, __doc__, "demo_hdri.png", argv)
    scene, scan, _ = build_scene(bpy, hdri_path(bpy, args.hdri), args.levels, args.width, args.height)
    equal_samples(scene, args.samples)
    render_both(bpy, scene, args, "demo-hdri",
                f"{len(scan.data.vertices):,} splats on an image-textured floor under Blender's '{args.hdri}' HDRI")
    return 0


if __name__ == "__main__":
    sys.exit(main())
