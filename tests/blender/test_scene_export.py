"""Whole scenes rendered through Blender (real bpy): what issue #7 asks of the scene renderer.

Clouds beside meshes under every lamp type against Cycles, point colours and textures,
instancing, the geometry cache across frames, view layers and holdout, ray visibility, the
ray counters, the passes, and a mirror. Images are small (160x120) and sample counts low;
set SPLAT_TRACER_TEST_IMAGES=/some/dir to keep a PNG of every render for a look.
"""
from __future__ import annotations

import math
import os
import time
from pathlib import Path

import numpy as np
import pytest

from blender_helpers import add_camera, extension_module
from geometry import fibonacci_sphere

W, H = 160, 120
# Blender 5.0 renamed three passes; the engine writes them under Blender's names.
DIFFCOL, EMIT, INDEX = "Diffuse Color", "Emission", "Object Index"


# --------------------------------------------------------------------------------------
# Building scenes.

def principled(bpy, name, base=(0.8, 0.8, 0.8), roughness=1.0, specular=0.0, metallic=0.0, emission=None):
    """A Principled BSDF material; the defaults are a pure diffuse one (no specular)."""
    material = bpy.data.materials.new(name)
    shader = material.node_tree.nodes["Principled BSDF"]
    shader.inputs["Base Color"].default_value = (*base, 1.0)
    shader.inputs["Roughness"].default_value = roughness
    shader.inputs["Specular IOR Level"].default_value = specular
    shader.inputs["Metallic"].default_value = metallic
    if emission is not None:
        shader.inputs["Emission Color"].default_value = (*emission[:3], 1.0)
        shader.inputs["Emission Strength"].default_value = emission[3]
    return material


def mesh_object(bpy, name, build, location=(0, 0, 0), materials=(), smooth=False, collection=None):
    """An object whose mesh `build(bm)` makes with bmesh."""
    import bmesh

    mesh = bpy.data.meshes.new(name)
    bm = bmesh.new()
    build(bm)
    bm.to_mesh(mesh)
    bm.free()
    if smooth:
        mesh.polygons.foreach_set("use_smooth", [True] * len(mesh.polygons))
    for m in materials:
        mesh.materials.append(m)
    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    (collection or bpy.context.scene.collection).objects.link(obj)
    return obj


def uv_sphere(bpy, name, radius, location, material, **kw):
    import bmesh
    return mesh_object(bpy, name, lambda bm: bmesh.ops.create_uvsphere(bm, u_segments=64, v_segments=32,
                                                                        radius=radius),
                       location, [material], smooth=True, **kw)


def plane(bpy, name, size, location, material, **kw):
    import bmesh
    return mesh_object(bpy, name, lambda bm: bmesh.ops.create_grid(bm, x_segments=1, y_segments=1, size=size / 2),
                       location, [material], **kw)


def cube(bpy, name, size, location, material, **kw):
    import bmesh
    return mesh_object(bpy, name, lambda bm: bmesh.ops.create_cube(bm, size=size), location, [material], **kw)


def cloud_sphere(bpy, name, n, radius, location, material=None, colours=None, collection=None):
    """A closed splat-cloud sphere (the importer's kind of object), splat radius 1.5x the
    mean spacing."""
    from splat_tracer.blender import cloud_object

    p, nrm = fibonacci_sphere(n, radius)
    radii = np.full(n, 1.5 * math.sqrt(4 * math.pi * radius ** 2 / n))
    obj = cloud_object.create_cloud_object(name, p, nrm, radii, colours, location=location, collection=collection)
    obj.splat_tracer.closed = True
    if material is not None:
        obj.data.materials.append(material)
    return obj


def lamp(bpy, kind, location=(0, 0, 0), rotation=(0, 0, 0), **settings):
    light = bpy.data.lights.new(kind.title(), kind)
    for key, value in settings.items():
        setattr(light, key, value)
    obj = bpy.data.objects.new(kind.title(), light)
    bpy.context.scene.collection.objects.link(obj)
    obj.location, obj.rotation_euler = location, rotation
    return obj


def black_world(bpy, scene):
    scene.world = bpy.data.worlds.new("Black")
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0, 0, 0, 1)


def direct_light_only(scene):
    """No bounces in either engine (ours reads its bounce limits from scene.cycles)."""
    c = scene.cycles
    c.max_bounces = c.diffuse_bounces = c.glossy_bounces = c.transmission_bounces = 0
    c.transparent_max_bounces = 0


# --------------------------------------------------------------------------------------
# Rendering and reading back.

def render(bpy, scene, path: Path, size=(W, H)) -> dict:
    """Renders to a multilayer EXR and reads it back: {layer: {pass: (H, W[, C])}}, top row
    first, channels in RGBA / XYZ(W) order."""
    import OpenEXR

    r = scene.render
    r.resolution_x, r.resolution_y = size
    r.resolution_percentage = 100
    r.image_settings.media_type = "MULTI_LAYER_IMAGE"
    r.image_settings.file_format = "OPEN_EXR_MULTILAYER"
    r.image_settings.color_depth = "32"
    r.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    channels = {}
    for part in OpenEXR.File(str(path), separate_channels=True).parts:
        channels.update({name: c.pixels for name, c in part.channels.items()})
    grouped: dict = {}
    for name in channels:
        layer, rest = name.split(".", 1)
        pass_name, letter = rest.rsplit(".", 1)
        grouped.setdefault(layer, {}).setdefault(pass_name, []).append(letter)
    out = {}
    for layer, passes in grouped.items():
        out[layer] = {}
        for pass_name, letters in passes.items():
            letters.sort(key="RGBXYZWUVA".index)  # W: the Vector pass's 4th; U, V, A: the UV pass
            arrays = [channels[f"{layer}.{pass_name}.{c}"] for c in letters]
            out[layer][pass_name] = arrays[0] if len(arrays) == 1 else np.stack(arrays, axis=-1)
    keep_png(path.stem, out)
    return out


def render_both(bpy, scene, tmp_path: Path, name: str, size=(W, H)) -> tuple:
    """The same scene rendered by this engine, then by Cycles (then this engine selected
    again): (ours, Cycles') passes of the first view layer, and our render report."""
    ours = render(bpy, scene, tmp_path / f"{name}_ours.exr", size)["ViewLayer"]
    report = list(stats()["report"])
    scene.render.engine = "CYCLES"
    try:
        theirs = render(bpy, scene, tmp_path / f"{name}_cycles.exr", size)["ViewLayer"]
    finally:
        scene.render.engine = "SPLAT_TRACER"
    return ours, theirs, report


def keep_png(name: str, out: dict) -> None:
    """Saves each layer's Combined as a PNG when SPLAT_TRACER_TEST_IMAGES names a folder."""
    folder = os.environ.get("SPLAT_TRACER_TEST_IMAGES")
    if not folder:
        return
    from PIL import Image

    Path(folder).mkdir(parents=True, exist_ok=True)
    for layer, passes in out.items():
        rgba = np.clip(passes["Combined"], 0, 1)
        rgba[..., :3] **= 1 / 2.2
        Image.fromarray((rgba * 255).astype(np.uint8), "RGBA").save(Path(folder) / f"{name}_{layer}.png")


def stats():
    """The last frame's stats of the enabled extension's session."""
    return extension_module("blender.session").HISTORY[-1]


def pixel_of(bpy, scene, world_point) -> tuple:
    """(row from the top, column) of a world point in the scene camera's image."""
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Vector

    p = world_to_camera_view(scene, scene.camera, Vector(world_point))
    return int((1 - p.y) * scene.render.resolution_y), int(p.x * scene.render.resolution_x)


def erode(mask, iterations=1):
    from scipy.ndimage import binary_erosion
    return binary_erosion(mask, iterations=iterations)


def iou(a, b) -> float:
    return (a & b).sum() / max((a | b).sum(), 1)


def luminance(rgb):
    return rgb[..., :3].mean(axis=-1)


# --------------------------------------------------------------------------------------
# 1. Brightness against Cycles, under each lamp type.

SPHERE_R, SPHERE_X = 0.7, 0.9  # the cloud at x = -0.9, the mesh sphere at x = +0.9
FLOOR, CLOUD, MESH = 1, 2, 3   # pass indices
# Every lamp lies in the plane x = 0, like the camera: the scene is mirror-symmetric, so the
# cloud's shadow (left) and the mesh sphere's (right) are mirror images of each other.
LAMPS = {
    "POINT": dict(location=(0, -1.0, 3.0), energy=200.0, shadow_soft_size=0.15),
    "SUN": dict(rotation=(math.radians(35), 0, 0), energy=3.0, angle=math.radians(3)),
    "SPOT": dict(location=(0, -1.5, 4.0), rotation=(math.radians(20), 0, 0), energy=400.0,
                 spot_size=math.radians(70), spot_blend=0.3, shadow_soft_size=0.1),
    "AREA": dict(location=(0, -1.0, 3.0), rotation=(math.radians(15), 0, 0), energy=60.0, size=1.0),
}
OURS_SAMPLES, CYCLES_SAMPLES = 32, 64


def lamp_scene_renders(bpy, kind, folder: Path) -> dict:
    """The cloud sphere and a UV sphere side by side on a mesh floor, one pure-diffuse
    material, a black world and direct light only, under one lamp: rendered by Splat
    Tracer (also once with the spheres casting no shadow: the unshadowed floor), and by
    Cycles with a mesh twin in the cloud's place (Cycles renders a cloud as balls, which is
    not the surface it samples)."""
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    diffuse = principled(bpy, "Diffuse")
    floor = plane(bpy, "Floor", 8.0, (0, 0, 0), diffuse)
    cloud = cloud_sphere(bpy, "Cloud", 8000, SPHERE_R, (-SPHERE_X, 0, SPHERE_R), diffuse)
    twin = uv_sphere(bpy, "Twin", SPHERE_R, (-SPHERE_X, 0, SPHERE_R), diffuse)
    sphere = uv_sphere(bpy, "Sphere", SPHERE_R, (SPHERE_X, 0, SPHERE_R), diffuse)
    floor.pass_index, cloud.pass_index, twin.pass_index, sphere.pass_index = FLOOR, CLOUD, CLOUD, MESH
    settings = dict(LAMPS[kind])
    lamp(bpy, kind, settings.pop("location", (0, 0, 0)), settings.pop("rotation", (0, 0, 0)), **settings)
    add_camera(bpy, scene, (0, -6, 3.2), (math.radians(65), 0, 0))
    black_world(bpy, scene)
    direct_light_only(scene)
    scene.view_settings.view_transform = "Standard"
    scene.render.filter_size = scene.cycles.filter_width = 0.01  # pixel-centre samples in both
    scene.cycles.device, scene.cycles.samples = "CPU", CYCLES_SAMPLES
    scene.cycles.use_denoising = scene.cycles.use_adaptive_sampling = False
    scene.splat_tracer.shadow_samples = 4
    scene.view_layers[0].use_pass_object_index = True
    out = {}
    scene.render.engine = "SPLAT_TRACER"
    scene.cycles.samples = OURS_SAMPLES  # the samples are Cycles' setting, read by both
    twin.hide_render = True
    out["ours"] = render(bpy, scene, folder / f"{kind.lower()}_ours.exr")["ViewLayer"]
    out["ours_stats"] = stats()
    cloud.visible_shadow = sphere.visible_shadow = False
    out["unshadowed"] = render(bpy, scene, folder / f"{kind.lower()}_unshadowed.exr")["ViewLayer"]
    cloud.visible_shadow = sphere.visible_shadow = True
    scene.render.engine = "CYCLES"
    scene.cycles.samples = CYCLES_SAMPLES
    twin.hide_render, cloud.hide_render = False, True
    t0 = time.perf_counter()
    out["cycles"] = render(bpy, scene, folder / f"{kind.lower()}_cycles.exr")["ViewLayer"]
    out["cycles_seconds"] = time.perf_counter() - t0
    return out


@pytest.fixture(scope="module")
def lamp_renders(blender, tmp_path_factory):
    """lamp type -> its renders, made once for the tests of this module that need them."""
    made = {}

    def get(kind):
        if kind not in made:
            made[kind] = lamp_scene_renders(blender, kind, tmp_path_factory.mktemp(kind.lower()))
        return made[kind]

    return get


def regions(r) -> dict:
    """Pixel masks shared by both renders: each sphere's lit region (Cycles' sphere brighter
    than a tenth of its brightest pixel, both renders agreeing on the object, one pixel off
    every edge) and a floor patch in the bottom quarter (seen from 32-40 degrees above)."""
    ours, cycles = r["ours"], r["cycles"]
    lum = luminance(cycles["Combined"])
    out = {}
    for name, index in (("cloud", CLOUD), ("mesh", MESH)):
        both = erode((ours[INDEX] == index) & (cycles[INDEX] == index))
        out[name] = both & (lum > 0.1 * lum[both].max())
    floor = erode((ours[INDEX] == FLOOR) & (cycles[INDEX] == FLOOR))
    floor[: int(0.75 * H)] = False
    out["floor"] = floor
    return out


def shadow_mask(r, which: str):
    """Floor pixels of render `which` darker than half the unshadowed floor."""
    floor = (r["ours"][INDEX] == FLOOR) & (r["unshadowed"][INDEX] == FLOOR) & (r[which][INDEX] == FLOOR)
    unshadowed = luminance(r["unshadowed"]["Combined"])
    return floor & (unshadowed > 0.01) & (luminance(r[which]["Combined"]) < 0.5 * unshadowed)


BRIGHTNESS_TOLERANCE = 0.03  # mean radiance over a region, relative to Cycles'


@pytest.mark.parametrize("kind", sorted(LAMPS))
def test_brightness_matches_cycles_under_each_lamp(blender, lamp_renders, kind):
    """Mean radiance over each sphere's lit region and over a floor patch within 3 % of
    Cycles' (64 samples, denoising off; the regions hold 1,000-3,000 pixels, so the noise
    of either render moves their means by well under 1 %). Measured: 1.1-1.5 % darker on
    the spheres, 1-2 % on the patch -- the core's diffuse lobe loses (1 - cos)^5 at grazing
    view (see test_diffuse_floor_at_grazing_view_matches_cycles). The cloud and the mesh
    sphere, mirror images of each other, agree within 1.5 % (measured: 0.2-0.3 %)."""
    r = lamp_renders(kind)
    masks = regions(r)
    ours, cycles = luminance(r["ours"]["Combined"]), luminance(r["cycles"]["Combined"])
    ratios = {}
    for name, mask in masks.items():
        assert mask.sum() > 500, (name, mask.sum())
        ratios[name] = ours[mask].mean() / cycles[mask].mean()
    print(f"{kind}: ours / Cycles {ratios}; Cycles took {r['cycles_seconds']:.2f} s")
    for name, ratio in ratios.items():
        assert abs(ratio - 1) < BRIGHTNESS_TOLERANCE, (kind, name, ratio)
    # The cloud against the mesh sphere, both ours: the same region mirrored.
    lit = masks["mesh"] & masks["cloud"][:, ::-1]
    assert lit.sum() > 500
    assert ours[:, ::-1][lit].mean() / ours[lit].mean() == pytest.approx(1, abs=0.015)
    s = r["ours_stats"]
    assert s["lights"] == 1 and s["instances"] == 3 and not s["headlight"]


@pytest.mark.parametrize("kind", sorted(LAMPS))
def test_cloud_shadow_covers_the_mesh_spheres_pixels(blender, lamp_renders, kind):
    """The cloud's shadow on the floor against (a) the shadow Cycles renders for a mesh
    sphere in the cloud's place and (b) the mirror image of our mesh sphere's shadow:
    intersection over union at least 0.9, areas within 5 % (measured: IoU 0.95-0.99, areas
    within 4 %; the rest is the noisy penumbra of the soft lamps and a pixel of silhouette)."""
    r = lamp_renders(kind)
    ours, cycles = shadow_mask(r, "ours"), shadow_mask(r, "cycles")
    left = np.zeros_like(ours)
    left[:, : W // 2] = True
    cloud_ours, cloud_cycles = ours & left, cycles & left
    sphere_mirrored = (ours & ~left)[:, ::-1]
    assert cloud_ours.sum() > 150, cloud_ours.sum()
    print(f"{kind}: shadow px ours {cloud_ours.sum()} Cycles {cloud_cycles.sum()} mesh mirrored "
          f"{sphere_mirrored.sum()}; IoU vs Cycles {iou(cloud_ours, cloud_cycles):.3f}, "
          f"vs mesh {iou(cloud_ours, sphere_mirrored):.3f}")
    for other in (cloud_cycles, sphere_mirrored):
        assert iou(cloud_ours, other) >= 0.9
        assert cloud_ours.sum() == pytest.approx(other.sum(), rel=0.05)


def test_diffuse_floor_at_grazing_view_matches_cycles(blender, lamp_renders):
    """The floor seen from 18-22 degrees above it, under the sun: within 3 % of Cycles.
    (It was 13.7 % darker while a Schlick Fresnel dimmed the diffuse at Specular IOR Level 0.)"""
    r = lamp_renders("SUN")
    floor = erode((r["ours"][INDEX] == FLOOR) & (r["cycles"][INDEX] == FLOOR))
    floor[int(0.4 * H):] = False
    ratio = luminance(r["ours"]["Combined"])[floor].mean() / luminance(r["cycles"]["Combined"])[floor].mean()
    print(f"grazing floor: ours / Cycles {ratio:.3f} over {floor.sum()} px")
    assert floor.sum() > 300
    assert abs(ratio - 1) < BRIGHTNESS_TOLERANCE


# --------------------------------------------------------------------------------------
# 2. Point colours through the importer's material; a texture falls back to its default.

RED, BLUE = (0.8, 0.1, 0.05), (0.05, 0.1, 0.8)
TEXTURED_DEFAULT = (0.2, 0.6, 0.3)


def top_down_sun_scene(bpy, scene, ortho_scale, strength=math.pi, tilt=30):
    """An orthographic camera looking straight down at z = 0 and a sun `tilt` degrees off
    the vertical (no highlight towards the camera); a black world."""
    add_camera(bpy, scene, (0, 0, 5), (0, 0, 0), type="ORTHO", ortho_scale=ortho_scale)
    lamp(bpy, "SUN", rotation=(math.radians(tilt), 0, 0), energy=strength)
    black_world(bpy, scene)


def test_point_colours_render_and_a_texture_falls_back_with_one_report_line(blender, empty_scene, tmp_path):
    """A flat cloud, red on its left half and blue on its right, with the importer's
    'Splat Cloud' material (Attribute node -> Base Color): the Diffuse Color pass is each
    point's colour x (1 - F0) = 0.96 within 2 %, and the lit colour keeps the hue (the
    other two channels below a fifth of the dominant one). Two quads sharing a material
    whose Base Color is fed by a Particle Info node (not evaluated) render the socket's default, and the
    report says so in exactly one line."""
    bpy = blender
    scene = empty_scene
    g = np.stack(np.meshgrid(np.linspace(-1, 1, 41), np.linspace(-1, 1, 41)), -1).reshape(-1, 2)
    colours = np.array([(*RED, 1.0) if x < 0 else (*BLUE, 1.0) for x, _ in g])
    from splat_tracer.blender import cloud_object
    cloud = cloud_object.create_cloud_object("Painted", np.column_stack([g, np.zeros(len(g))]),
                                             np.tile([0.0, 0.0, 1.0], (len(g), 1)), np.full(len(g), 0.08),
                                             colours, location=(-1.2, 0, 0))
    textured = principled(bpy, "Textured", base=TEXTURED_DEFAULT)
    nodes = textured.node_tree.nodes
    unknown = nodes.new("ShaderNodeParticleInfo")  # a node materials do not evaluate (docs/nodes.md)
    textured.node_tree.links.new(unknown.outputs["Velocity"], nodes["Principled BSDF"].inputs["Base Color"])
    plane(bpy, "Quad1", 0.8, (1.2, 0.6, 0), textured)
    plane(bpy, "Quad2", 0.8, (1.2, -0.6, 0), textured)
    top_down_sun_scene(bpy, scene, 5.0)
    scene.view_layers[0].use_pass_diffuse_color = True
    out = render(bpy, scene, tmp_path / "colours.exr")["ViewLayer"]
    diffcol, combined = out[DIFFCOL], out["Combined"][..., :3]

    def patch(x, y):  # 5x5 pixels around a world point on the ground
        row, col = pixel_of(bpy, scene, (x, y, 0))
        return (slice(row - 2, row + 3), slice(col - 2, col + 3))

    evaluated = [i.object for i in bpy.context.evaluated_depsgraph_get().object_instances
                 if i.object.type == "POINTCLOUD" and i.object.original == cloud]
    assert [m.name for m in evaluated[0].data.materials] == ["Splat Cloud"]  # the importer's material
    for x, colour in ((-1.7, RED), (-0.7, BLUE)):
        np.testing.assert_allclose(diffcol[patch(x, 0.3)].reshape(-1, 3), np.tile(np.multiply(colour, 0.96), (25, 1)),
                                   rtol=0.02)
        lit = combined[patch(x, -0.3)].reshape(-1, 3).mean(axis=0)
        dominant = int(np.argmax(colour))
        assert lit[dominant] > 0.3 and all(lit[k] < 0.2 * lit[dominant] for k in range(3) if k != dominant), lit
    for y in (0.6, -0.6):
        np.testing.assert_allclose(diffcol[patch(1.2, y)].reshape(-1, 3), np.tile(TEXTURED_DEFAULT, (25, 1)),
                                   rtol=1e-3)
    lines = [line for line in stats()["report"] if "Textured" in line]
    assert lines == ["material 'Textured': the 'Particle Info' node is not supported; Base Color uses its unlinked "
                     "value (0.2, 0.6, 0.3)"], stats()["report"]


# --------------------------------------------------------------------------------------
# 3. Instances share one geometry.

INSTANCE_SPOTS = ((-1.2, 0.8, 0), (1.2, 0.8, 0), (-1.2, -0.8, 0), (1.2, -0.8, 0))
BALL_R = 0.3


def instance_with_geometry_nodes(bpy, ball, spots=INSTANCE_SPOTS):
    """An object whose Geometry Nodes put an instance of `ball` on each of its vertices, at
    `spots` (x, y, z)."""
    mesh = bpy.data.meshes.new("Spots")
    mesh.from_pydata(list(spots), [], [])
    holder = bpy.data.objects.new("Spots", mesh)
    bpy.context.scene.collection.objects.link(holder)
    group = bpy.data.node_groups.new("Instancer", "GeometryNodeTree")
    group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = group.nodes, group.links
    inp, out = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    info, on_points = nodes.new("GeometryNodeObjectInfo"), nodes.new("GeometryNodeInstanceOnPoints")
    info.inputs["Object"].default_value = ball
    info.inputs["As Instance"].default_value = True
    links.new(inp.outputs[0], on_points.inputs["Points"])
    links.new(info.outputs["Geometry"], on_points.inputs["Instance"])
    links.new(on_points.outputs["Instances"], out.inputs[0])
    holder.modifiers.new("Instances", "NODES").node_group = group


@pytest.mark.parametrize("how", ["collection", "geometry_nodes"])
def test_instances_of_one_cloud_share_one_geometry(blender, empty_scene, tmp_path, how):
    """A cloud at the origin and 4 instances of it (Empties instancing its collection, or
    Geometry Nodes' Instance on Points): all 5 render -- each a disc of the ball's
    projected area within 10 % around its projected centre -- and the frame built one
    geometry of 3,000 splats for 5 instances."""
    bpy = blender
    scene = empty_scene
    source = bpy.data.collections.new("Source")
    scene.collection.children.link(source)
    ball = cloud_sphere(bpy, "Ball", 3000, BALL_R, (0, 0, 0), principled(bpy, "Grey"), collection=source)
    if how == "collection":
        for i, spot in enumerate(INSTANCE_SPOTS):
            empty = bpy.data.objects.new(f"Empty{i}", None)
            empty.instance_type, empty.instance_collection, empty.location = "COLLECTION", source, spot
            scene.collection.objects.link(empty)
    else:
        instance_with_geometry_nodes(bpy, ball)
    top_down_sun_scene(bpy, scene, 4.0)
    scene.render.film_transparent = True
    alpha = render(bpy, scene, tmp_path / f"instances_{how}.exr")["ViewLayer"]["Combined"][..., 3]
    s = stats()
    assert (s["instances"], s["geometries"], s["splats"]) == (5, 1, 3000), s
    assert s["built"] <= 1
    from scipy.ndimage import label
    blobs, count = label(alpha > 0.5)
    assert count == 5
    pixel_area = math.pi * (BALL_R / (4.0 / W)) ** 2
    for spot in ((0, 0, 0),) + INSTANCE_SPOTS:
        row, col = pixel_of(bpy, scene, spot)
        assert alpha[row - 3:row + 4, col - 3:col + 4].min() == 1.0, spot
        assert (blobs == blobs[row, col]).sum() == pytest.approx(pixel_area, rel=0.1), spot


# --------------------------------------------------------------------------------------
# 4. The geometry cache across frames.

def small_scene(bpy, scene):
    """A cloud and a mesh cube, a sun, a camera keyframed to move between frames 1 and 2."""
    grey = principled(bpy, "Grey")
    cloud_sphere(bpy, "Ball", 3000, 0.6, (-0.8, 0, 0), grey)
    cube(bpy, "Box", 1.0, (0.8, 0, 0), grey)
    lamp(bpy, "SUN", rotation=(math.radians(30), 0, 0), energy=3.0)
    cam = add_camera(bpy, scene, (0, -6, 0), (math.radians(90), 0, 0))
    cam.keyframe_insert("location", frame=1)
    cam.location = (0.5, -5, 0.5)
    cam.keyframe_insert("location", frame=2)
    scene.frame_start, scene.frame_end = 1, 2
    scene.frame_set(1)
    scene.render.resolution_x, scene.render.resolution_y = 80, 60
    scene.cycles.samples = 2


def test_an_animation_where_only_the_camera_moves_builds_its_geometry_once(blender, empty_scene, tmp_path):
    """Two frames rendered with bpy.ops.render.render(animation=True): frame 2 builds
    nothing and reuses both geometries; the frames differ; after the job the cache is empty
    (it kept the BVHs until the next render before)."""
    bpy = blender
    scene = empty_scene
    session = extension_module("blender.session")
    small_scene(bpy, scene)
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = str(tmp_path / "frame_")
    session.HISTORY.clear()  # it keeps the last 100 frames: a count from before could stand still
    bpy.ops.render.render(animation=True)
    first, second = session.HISTORY
    assert (first["frame"], second["frame"]) == (1, 2)
    assert (first["built"], first["reused"]) == (2, 0)
    assert (second["built"], second["reused"], second["geometries"]) == (0, 2, 2)
    frames = sorted(tmp_path.glob("frame_*.png"))
    assert [f.name for f in frames] == ["frame_0001.png", "frame_0002.png"]
    assert frames[0].read_bytes() != frames[1].read_bytes()
    assert session.CACHE.entries == {}


def test_persistent_data_keeps_the_geometry_between_renders(blender, empty_scene, tmp_path):
    """With Persistent Data two F12 renders in a row: the second builds nothing. Without
    it, the cache is empty after a render, and the next render builds again."""
    bpy = blender
    scene = empty_scene
    session = extension_module("blender.session")
    small_scene(bpy, scene)
    scene.render.use_persistent_data = True
    bpy.ops.render.render()
    assert (stats()["built"], len(session.CACHE.entries)) == (2, 2)
    scene.frame_set(2)  # the camera moved
    bpy.ops.render.render()
    assert (stats()["built"], stats()["reused"]) == (0, 2)
    assert len(session.CACHE.entries) == 2
    scene.render.use_persistent_data = False
    bpy.ops.render.render()
    assert stats()["built"] == 0 and session.CACHE.entries == {}
    bpy.ops.render.render()
    assert (stats()["built"], stats()["reused"]) == (2, 0) and session.CACHE.entries == {}


# --------------------------------------------------------------------------------------
# 5. View layers and holdout.

def test_view_layers_render_each_into_its_own_layer(blender, empty_scene, tmp_path):
    """Layer A shows the cloud's collection, layer B the cube's (each excludes the other):
    one multilayer EXR holds both; each layer's alpha covers its own object's pixels only."""
    bpy = blender
    scene = empty_scene
    grey = principled(bpy, "Grey")
    clouds, cubes = bpy.data.collections.new("Clouds"), bpy.data.collections.new("Cubes")
    scene.collection.children.link(clouds)
    scene.collection.children.link(cubes)
    cloud_sphere(bpy, "Ball", 3000, 0.6, (-1.0, 0, 0), grey, collection=clouds)
    cube(bpy, "Box", 1.0, (1.0, 0, 0), grey, collection=cubes)
    lamp(bpy, "SUN", rotation=(math.radians(30), 0, 0), energy=3.0)
    add_camera(bpy, scene, (0, -6, 0), (math.radians(90), 0, 0))
    scene.render.film_transparent = True
    a = scene.view_layers[0]
    a.name = "A"
    b = scene.view_layers.new("B")
    a.layer_collection.children["Cubes"].exclude = True
    b.layer_collection.children["Clouds"].exclude = True
    out = render(bpy, scene, tmp_path / "layers.exr")
    assert sorted(out) == ["A", "B"]
    alpha_a, alpha_b = out["A"]["Combined"][..., 3], out["B"]["Combined"][..., 3]
    ball, box = pixel_of(bpy, scene, (-1.0, 0, 0)), pixel_of(bpy, scene, (1.0, 0, 0))
    assert alpha_a[ball] == 1.0 and alpha_a[box] == 0.0
    assert alpha_b[box] == 1.0 and alpha_b[ball] == 0.0
    left = np.zeros((H, W), bool)
    left[:, : W // 2] = True
    assert (alpha_a[~left] == 0).all() and (alpha_b[left] == 0).all()  # nothing of the other
    assert (alpha_a > 0).sum() > 500 and (alpha_b > 0).sum() > 500
    history = extension_module("blender.session").HISTORY
    assert sorted((h["view_layer"], h["instances"]) for h in history[-2:]) == [("A", 1), ("B", 1)]


@pytest.mark.parametrize("how", ["collection", "object"])
def test_holdout_cuts_alpha_where_it_covers_the_cloud(blender, empty_scene, tmp_path, how):
    """A quad in front of the cloud's left half, held out by its collection's Holdout in
    the view layer or by the object's own: where it covers the cloud, alpha is 0 (it was 1
    without holdout, the quad visible); the rest of the cloud keeps alpha 1."""
    bpy = blender
    scene = empty_scene
    grey = principled(bpy, "Grey")
    cloud_sphere(bpy, "Ball", 4000, 1.0, (0, 0, 0), grey)
    masks = bpy.data.collections.new("Masks")
    scene.collection.children.link(masks)
    quad = plane(bpy, "Mask", 2.0, (-1.0, -1.5, 0), grey, collection=masks)
    quad.rotation_euler = (math.radians(90), 0, 0)
    quad.pass_index = 5
    lamp(bpy, "SUN", rotation=(math.radians(30), 0, 0), energy=3.0)
    add_camera(bpy, scene, (0, -6, 0), (math.radians(90), 0, 0), type="ORTHO", ortho_scale=4.0)
    scene.render.film_transparent = True
    scene.view_layers[0].use_pass_object_index = True
    plain = render(bpy, scene, tmp_path / "no_holdout.exr")["ViewLayer"]
    if how == "collection":
        scene.view_layers[0].layer_collection.children["Masks"].holdout = True
    else:
        quad.is_holdout = True
    held = render(bpy, scene, tmp_path / f"holdout_{how}.exr")["ViewLayer"]
    # The quad's pixels in front of the ball (its projected disc, 1.5 pixels in from the rim).
    rows, cols = np.mgrid[:H, :W]
    row, col = pixel_of(bpy, scene, (0, 0, 0))
    disc = np.hypot(rows + 0.5 - row, cols + 0.5 - col) < 1.0 / (4.0 / W) - 1.5
    in_front = erode(plain[INDEX] == 5) & disc
    cloud = erode((plain[INDEX] == 0) & (plain["Combined"][..., 3] == 1.0))  # the half not covered
    assert in_front.sum() > 1000 and cloud.sum() > 1000
    assert (plain["Combined"][..., 3][in_front] == 1.0).all()
    assert (held["Combined"][..., 3][in_front] == 0.0).all()
    assert (held["Combined"][..., 3][cloud] == 1.0).all()


# --------------------------------------------------------------------------------------
# 6. Ray visibility.

def shadow_scene(bpy, scene):
    """A cloud sphere floating over a mesh floor under a slanted sun, seen from above."""
    grey = principled(bpy, "Grey")
    floor = plane(bpy, "Floor", 8.0, (0, 0, 0), grey)
    ball = cloud_sphere(bpy, "Ball", 4000, 0.6, (0, 0, 1.0), grey)
    floor.pass_index, ball.pass_index = FLOOR, CLOUD
    # The sun shines from behind the ball: its shadow falls towards the camera, in view.
    lamp(bpy, "SUN", rotation=(math.radians(-35), 0, 0), energy=3.0)
    add_camera(bpy, scene, (0, -3, 6), (math.radians(25), 0, 0))
    black_world(bpy, scene)
    direct_light_only(scene)
    layer = scene.view_layers[0]
    layer.use_pass_object_index = layer.use_pass_shadow = True
    return ball


def test_ray_visibility_camera_and_shadow(blender, empty_scene, tmp_path):
    """Camera visibility off: the cloud's pixels show the floor and its shadow stays (the
    same shadow pixels where the floor was seen before, IoU >= 0.95; measured 0.99). Shadow visibility off: the cloud is seen and casts
    no shadow (Shadow pass at 1 on every floor pixel)."""
    bpy = blender
    scene = empty_scene
    ball = shadow_scene(bpy, scene)
    seen = render(bpy, scene, tmp_path / "visible.exr")["ViewLayer"]
    ball.visible_camera = False
    hidden = render(bpy, scene, tmp_path / "camera_off.exr")["ViewLayer"]
    ball.visible_camera, ball.visible_shadow = True, False
    no_shadow = render(bpy, scene, tmp_path / "shadow_off.exr")["ViewLayer"]

    def shadow(out):
        return (out[INDEX] == FLOOR) & (out["Shadow"][..., 0] < 0.5)

    on_ball = seen[INDEX] == CLOUD
    assert on_ball.sum() > 800 and shadow(seen).sum() > 800
    assert not (shadow(seen) & on_ball).any()  # the shadow falls beside the ball, in view
    assert (hidden[INDEX] != CLOUD).all() and (hidden[INDEX][on_ball] == FLOOR).all()
    assert iou(shadow(hidden) & ~on_ball, shadow(seen)) >= 0.95  # where the floor is seen in both
    assert shadow(hidden)[on_ball].sum() > 100  # and it goes on under where the ball was seen
    assert ((no_shadow[INDEX] == CLOUD) == on_ball).all()
    floor = no_shadow[INDEX] == FLOOR
    assert (no_shadow["Shadow"][floor] == 1.0).all()


# --------------------------------------------------------------------------------------
# 7. What each kind of scene traces.

def counters_scene(bpy, scene, material):
    cloud_sphere(bpy, "Ball", 3000, 0.6, (-0.8, 0, 0.6), material)
    plane(bpy, "Floor", 6.0, (0, 0, 0), material)
    uv_sphere(bpy, "Sphere", 0.6, (0.8, 0, 0.6), material)
    add_camera(bpy, scene, (0, -5, 2.5), (math.radians(70), 0, 0))
    black_world(bpy, scene)
    scene.render.resolution_x, scene.render.resolution_y = 80, 60
    scene.cycles.samples = 4


def diffuse_bsdf(bpy, name="Matte"):
    material = bpy.data.materials.new(name)
    nodes = material.node_tree.nodes
    nodes.remove(nodes["Principled BSDF"])
    shader = nodes.new("ShaderNodeBsdfDiffuse")
    material.node_tree.links.new(shader.outputs[0], nodes["Material Output"].inputs["Surface"])
    return material


RAYS = ("shadow_rays", "reflection_rays", "refraction_rays", "diffuse_rays", "transparent_rays")


def test_an_unlit_scene_falls_back_to_the_headlight_and_traces_nothing_else(blender, empty_scene, tmp_path):
    """No lamp, a black world, diffuse materials: one camera ray per sample and nothing
    else, and the report says it fell back to the headlight."""
    bpy = blender
    scene = empty_scene
    counters_scene(bpy, scene, diffuse_bsdf(bpy))
    out = render(bpy, scene, tmp_path / "unlit.exr", size=(80, 60))["ViewLayer"]
    s = stats()
    assert s["headlight"] and s["camera_rays"] == 80 * 60 * 4
    assert {k: s[k] for k in RAYS} == dict.fromkeys(RAYS, 0)
    assert [line for line in s["report"] if "headlight" in line] == [
        "the scene has no lamp, no emission and a black world: rendered with a headlight (Splat Tracer > Lighting)"]
    assert luminance(out["Combined"]).max() > 0.5  # the headlight does light it


def test_a_lit_diffuse_scene_traces_shadow_and_diffuse_rays_only(blender, empty_scene, tmp_path):
    """A lamp and diffuse materials (Cycles' default bounces): shadow and diffuse rays, no
    refraction and no transparency; glass adds refraction rays (the counter counts)."""
    bpy = blender
    scene = empty_scene
    counters_scene(bpy, scene, diffuse_bsdf(bpy))
    lamp(bpy, "POINT", (0, -1, 3), energy=300.0)
    render(bpy, scene, tmp_path / "lit.exr", size=(80, 60))
    s = stats()
    assert not s["headlight"] and s["shadow_rays"] > 0 and s["diffuse_rays"] > 0
    assert s["refraction_rays"] == 0 and s["transparent_rays"] == 0
    glass = principled(bpy, "Glass", roughness=0.0, specular=0.5)
    glass.node_tree.nodes["Principled BSDF"].inputs["Transmission Weight"].default_value = 1.0
    bpy.data.objects["Sphere"].data.materials[0] = glass
    render(bpy, scene, tmp_path / "glass.exr", size=(80, 60))
    assert stats()["refraction_rays"] > 0


def test_a_lit_diffuse_scene_traces_no_reflection_rays(blender, empty_scene, tmp_path):
    """Diffuse BSDFs reflect nothing specularly: Cycles traces no glossy ray for them."""
    bpy = blender
    scene = empty_scene
    counters_scene(bpy, scene, diffuse_bsdf(bpy))
    lamp(bpy, "POINT", (0, -1, 3), energy=300.0)
    render(bpy, scene, tmp_path / "lit.exr", size=(80, 60))
    print("reflection rays of a diffuse scene:", stats()["reflection_rays"], "of", stats()["diffuse_rays"],
          "diffuse rays")
    assert stats()["reflection_rays"] == 0


# --------------------------------------------------------------------------------------
# 8. Passes.

PASS_SWITCHES = ("use_pass_diffuse_color", "use_pass_emit", "use_pass_shadow", "use_pass_object_index")


def passes_scene(bpy, scene):
    """From straight above (orthographic): a floor (metallic 0.5, no specular), a cloud
    sphere on it casting a shadow, an emissive cube. Pass indices 3 (floor), 7 (cloud), 0."""
    floor_material = principled(bpy, "Half Metal", base=(0.6, 0.3, 0.1), metallic=0.5)
    floor = plane(bpy, "Floor", 8.0, (0, 0, 0), floor_material)
    ball = cloud_sphere(bpy, "Ball", 4000, 0.5, (-0.8, 0.3, 0.5), principled(bpy, "Grey"))
    cube(bpy, "Glow", 0.6, (1.0, -0.5, 0.3), principled(bpy, "Glow", base=(0, 0, 0), emission=(1.0, 0.5, 0.25, 2.0)))
    floor.pass_index, ball.pass_index = 3, 7
    top_down_sun_scene(bpy, scene, 4.0, strength=3.0, tilt=40)
    return floor, ball


def test_passes_hold_plausible_values_and_only_the_enabled_ones_exist(blender, empty_scene, tmp_path):
    """Diffuse Color on the flat-lit floor = base x (1 - metallic) (no specular: the diffuse
    share is all the rest), to 0.1 %; Emission = colour x strength on the cube's top, 0 on
    the floor; Shadow 0 in the ball's shadow, 1 in the open; Object Index = each object's
    pass index, 0 on the cube; Splat Count > 1 on the cloud, 0 on the floor. Passes not
    enabled are absent; the pass names are those Cycles gives the same passes."""
    bpy = blender
    scene = empty_scene
    floor, ball = passes_scene(bpy, scene)
    layer = scene.view_layers[0]
    out = render(bpy, scene, tmp_path / "no_passes.exr")["ViewLayer"]
    assert sorted(out) == ["Combined"]
    for switch in PASS_SWITCHES:
        setattr(layer, switch, True)
    layer.splat_tracer.use_pass_splat_count = True
    out = render(bpy, scene, tmp_path / "passes.exr")["ViewLayer"]
    assert sorted(out) == sorted(["Combined", DIFFCOL, EMIT, "Shadow", INDEX, "Splat Count"])

    def at(x, y, z=0.0):
        return pixel_of(bpy, scene, (x, y, z))

    open_floor, glow_top, ball_top = at(1.2, 1.2), at(1.0, -0.5, 0.6), at(-0.8, 0.3, 1.0)
    shadowed = at(-0.8, 0.3 + 0.9 * math.tan(math.radians(40)))  # beside the ball, away from the sun
    np.testing.assert_allclose(out[DIFFCOL][open_floor], [0.3, 0.15, 0.05], rtol=1e-3)
    np.testing.assert_allclose(out[EMIT][glow_top], [2.0, 1.0, 0.5], rtol=1e-4)
    np.testing.assert_array_equal(out[EMIT][open_floor], [0, 0, 0])
    assert out["Shadow"][open_floor][0] == 1.0 and out["Shadow"][shadowed][0] == 0.0
    assert out[INDEX][open_floor] == 3 and out[INDEX][ball_top] == 7 and out[INDEX][glow_top] == 0
    count = out["Splat Count"]
    on_ball = out[INDEX] == 7
    assert on_ball.sum() > 500 and count[on_ball].min() >= 1 and np.median(count[on_ball]) > 1
    assert (count[~on_ball] == 0).all()
    # Turned off again, each pass is gone.
    layer.use_pass_emit = False
    layer.splat_tracer.use_pass_splat_count = False
    out = render(bpy, scene, tmp_path / "fewer.exr")["ViewLayer"]
    assert sorted(out) == sorted(["Combined", DIFFCOL, "Shadow", INDEX])


def test_pass_names_are_the_ones_cycles_uses(blender, empty_scene):
    """The compositor's Render Layers node offers the same sockets for our passes as for
    Cycles' (Blender 5 renamed DiffCol, Emit and IndexOB), so node setups survive a switch
    of engine."""
    bpy = blender
    scene = empty_scene
    layer = scene.view_layers[0]
    for switch in ("use_pass_z", "use_pass_normal", "use_pass_diffuse_color", "use_pass_emit",
                   "use_pass_object_index"):
        setattr(layer, switch, True)
    tree = bpy.data.node_groups.new("Compositing", "CompositorNodeTree")
    scene.compositing_node_group = tree
    node = tree.nodes.new("CompositorNodeRLayers")
    sockets = {}
    for engine in ("CYCLES", "SPLAT_TRACER"):
        scene.render.engine = engine
        sockets[engine] = {s.name for s in node.outputs if s.enabled}
    assert {"Depth", "Normal", DIFFCOL, EMIT, INDEX} <= sockets["SPLAT_TRACER"]
    assert sockets["SPLAT_TRACER"] <= sockets["CYCLES"]


# --------------------------------------------------------------------------------------
# 9. A mirror sphere over a checker floor.

def checker_floor(bpy, n=10, size=6.0):
    """A grid of n x n faces alternating between a red and a green material."""
    import bmesh

    red, green = principled(bpy, "Red", base=(0.8, 0.05, 0.05)), principled(bpy, "Green", base=(0.05, 0.8, 0.05))

    def build(bm):
        bmesh.ops.create_grid(bm, x_segments=n, y_segments=n, size=size / 2)
        for face in bm.faces:
            c = face.calc_center_median()
            face.material_index = (int((c.x + size / 2) // (size / n)) + int((c.y + size / 2) // (size / n))) % 2

    return mesh_object(bpy, "Checker", build, materials=(red, green))


def mirror_scene(bpy, scene):
    checker_floor(bpy)
    ball = cloud_sphere(bpy, "Mirror", 6000, 0.8, (0, 0, 0.8), principled(bpy, "Chrome", base=(0.9, 0.9, 0.9),
                                                                          roughness=0.0, metallic=1.0))
    ball.pass_index = CLOUD
    lamp(bpy, "SUN", rotation=(math.radians(30), 0, math.radians(20)), energy=3.0)
    add_camera(bpy, scene, (0, -4.5, 2.0), (math.radians(72), 0, 0))
    scene.world = bpy.data.worlds.new("Grey")
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.05, 0.05, 0.05, 1)
    scene.view_layers[0].use_pass_object_index = True
    scene.cycles.samples = 1  # one ray per pixel: a wrong hit is a whole pixel, not a quarter


def speckles(rgb, mask) -> int:
    """Pixels of `mask` off the median of their 3x3 neighbourhood by more than 30 % (and
    0.003): isolated specks, not the reflection's edges (a checker edge has as many pixels
    on each side, so the median follows it)."""
    from scipy.ndimage import median_filter
    lum = luminance(rgb)
    median = median_filter(lum, size=3)
    return int((np.abs(lum - median) > 0.3 * median + 0.003)[erode(mask)].sum())


def test_mirror_cloud_reflects_the_checker_and_the_full_method_has_fewer_speckles(blender, empty_scene, tmp_path):
    """A mirror cloud sphere (metallic 1, roughness 0) over a red/green checker floor:
    its pixels show both checker colours (each in at least 100 pixels), and the general
    method (plain splat ray tracing: reflection rays may hit the sphere's own discs) has at
    least twice as many isolated specks on the sphere as the full method."""
    bpy = blender
    scene = empty_scene
    mirror_scene(bpy, scene)
    full = render(bpy, scene, tmp_path / "mirror_full.exr")["ViewLayer"]
    rgb, on_ball = full["Combined"][..., :3], full[INDEX] == CLOUD
    assert on_ball.sum() > 1500
    red = on_ball & (rgb[..., 0] > 2 * rgb[..., 1]) & (rgb[..., 0] > 0.05)
    green = on_ball & (rgb[..., 1] > 2 * rgb[..., 0]) & (rgb[..., 1] > 0.05)
    assert red.sum() >= 100 and green.sum() >= 100, (red.sum(), green.sum())
    assert stats()["reflection_rays"] > 0
    scene.splat_tracer.method = "GENERAL"
    general = render(bpy, scene, tmp_path / "mirror_general.exr")["ViewLayer"]
    n_full = speckles(full["Combined"], on_ball)
    n_general = speckles(general["Combined"], on_ball & (general[INDEX] == CLOUD))
    print(f"speckles on the mirror: full {n_full}, general {n_general}")
    assert n_general >= 2 * max(n_full, 10)
