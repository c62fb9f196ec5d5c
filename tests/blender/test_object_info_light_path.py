"""Object Info, Light Path and object-type Attribute nodes through Blender, side by side with Cycles.

Per-object values (issue 24): tiles of one emissive material whose colour comes from Object
Info (Random through a Color Ramp, Object Index, Location, Color) or an object attribute,
each tile's colour read at its centre; objects, linked duplicates and a collection instance's
copies (whose Random is Blender's per-instance id). Light Path: an emissive sphere red to the
camera and green to every other ray over a white floor (the floor's tint), and a block whose
material is transparent to shadow rays (no shadow). Orthographic camera straight down, black
world, CPU Cycles without denoising.

Tolerances (measured with bpy 5.0.1; each test also shows that a wrong render fails):
- TILE_ATOL = 0.01: each tile's colour (emission seen directly: no noise; measured equal to
  4 decimals); a Random off by one object (another tile's value) is far outside.
- FLOOR_RTOL = 0.15: a floor's mean colour lit by an emissive sphere (Monte Carlo noise at 64
  samples in both engines; measured 0.8 % apart) and a shadow region (measured equal to 5
  digits). Without the Light Path node the floor is lit red and the block casts its shadow:
  far outside.
"""
from __future__ import annotations

import math

import numpy as np

from blender_helpers import add_camera
from test_scene_export import black_world, cube, direct_light_only, instance_with_geometry_nodes, lamp, mesh_object, \
    plane, principled, render, render_both, stats, uv_sphere

SIZE = 64
TILE_ATOL = 0.01
FLOOR_RTOL = 0.15
TILES = [(-0.75, -0.75), (0.0, -0.75), (0.75, -0.75), (-0.75, 0.0), (0.75, 0.0), (-0.75, 0.75), (0.0, 0.75)]


def _square(bpy, name, size, location, material, collection=None):
    import bmesh

    def build(bm):
        bmesh.ops.create_grid(bm, x_segments=1, y_segments=1, size=size / 2)

    return mesh_object(bpy, name, build, location, [material], collection=collection)


def _setup(bpy, scene, samples=4):
    add_camera(bpy, scene, (0, 0, 5), (0, 0, 0), type="ORTHO", ortho_scale=2.4)
    black_world(bpy, scene)
    direct_light_only(scene)
    c = scene.cycles
    c.samples, c.device, c.use_denoising, c.use_adaptive_sampling = samples, "CPU", False, False


def _emissive(bpy, name):
    """A material whose Emission colour the caller links; (material, nodes, links, emission)."""
    m = bpy.data.materials.new(name)
    nodes, links = m.node_tree.nodes, m.node_tree.links
    nodes.remove(nodes["Principled BSDF"])
    emission = nodes.new("ShaderNodeEmission")
    links.new(emission.outputs[0], nodes["Material Output"].inputs["Surface"])
    return m, nodes, links, emission


def _both(bpy, scene, tmp_path, name):
    ours, theirs, report = render_both(bpy, scene, tmp_path, name, (SIZE, SIZE))
    return ours["Combined"][..., :3], theirs["Combined"][..., :3], report


def _at(image, x, y):
    """The mean colour of a 3x3 block around the scene point (x, y) (the ortho view spans 2.4 m)."""
    col = int((x / 2.4 + 0.5) * SIZE)
    row = int((0.5 - y / 2.4) * SIZE)
    return image[row - 1:row + 2, col - 1:col + 2].reshape(-1, 3).mean(0)


def _tiles(bpy, material, count=len(TILES)):
    objects = []
    for i, (x, y) in enumerate(TILES[:count]):
        obj = _square(bpy, f"Tile{i}", 0.5, (x, y, 0), material)
        obj.pass_index = i + 1
        obj.color = (0.1 * i, 1.0 - 0.1 * i, 0.5, 1.0)
        objects.append(obj)
    return objects


def test_object_info_random_per_object_and_instance_matches_cycles(blender, empty_scene, tmp_path):
    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emissive(bpy, "RandomRamp")
    info = nodes.new("ShaderNodeObjectInfo")
    ramp = nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.elements[0].color = (0.0, 0.0, 1.0, 1.0)
    ramp.color_ramp.elements[1].color = (1.0, 0.5, 0.0, 1.0)
    links.new(info.outputs["Random"], ramp.inputs[0])
    links.new(ramp.outputs["Color"], emission.inputs["Color"])
    tiles = _tiles(bpy, m, count=4)
    tiles[3].name = "Tuile grisée"  # non-ASCII bytes in the name's hash
    # A linked duplicate (same mesh, its own name) and two copies of a collection instance.
    dup = tiles[0].copy()
    dup.name = "LinkedDuplicate"
    dup.location = TILES[4] + (0,)
    scene.collection.objects.link(dup)
    hidden = bpy.data.collections.new("Instanced")
    _square(bpy, "InstancedTile", 0.5, (0, 0, 0), m, collection=hidden)
    for k, (x, y) in enumerate(TILES[5:]):
        empty = bpy.data.objects.new(f"Instancer{k}", None)
        empty.instance_type, empty.instance_collection = "COLLECTION", hidden
        empty.location = (x, y, 0)
        scene.collection.objects.link(empty)
    _setup(bpy, scene)
    ours, theirs, report = _both(bpy, scene, tmp_path, "random")
    got = np.array([_at(ours, x, y) for x, y in TILES])
    want = np.array([_at(theirs, x, y) for x, y in TILES])
    np.testing.assert_allclose(got, want, atol=TILE_ATOL)
    assert not [line for line in report if "RandomRamp" in line], report
    # The tiles differ from one another (the test can see a wrong Random): shifting the
    # values by one object puts them far outside.
    assert np.abs(np.roll(got, 1, axis=0) - want).max() > 10 * TILE_ATOL


def test_object_index_location_and_colour_match_cycles(blender, empty_scene, tmp_path):
    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emissive(bpy, "IndexLocation")
    info = nodes.new("ShaderNodeObjectInfo")
    # Colour: (index / 10, location x + 1, location y + 1) + the object's colour / 4.
    sep = nodes.new("ShaderNodeSeparateXYZ")
    links.new(info.outputs["Location"], sep.inputs[0])
    comb = nodes.new("ShaderNodeCombineXYZ")
    div = nodes.new("ShaderNodeMath")
    div.operation, div.inputs[1].default_value = "DIVIDE", 10.0
    links.new(info.outputs["Object Index"], div.inputs[0])
    links.new(div.outputs[0], comb.inputs[0])
    for axis, name in ((1, "X"), (2, "Y")):
        add = nodes.new("ShaderNodeMath")
        add.operation, add.inputs[1].default_value = "ADD", 1.0
        links.new(sep.outputs[name], add.inputs[0])
        links.new(add.outputs[0], comb.inputs[axis])
    mix = nodes.new("ShaderNodeMix")
    mix.data_type, mix.blend_type = "RGBA", "ADD"
    mix.inputs["Factor"].default_value = 0.25
    links.new(comb.outputs[0], mix.inputs["A"])
    links.new(info.outputs["Color"], mix.inputs["B"])
    links.new(mix.outputs["Result"], emission.inputs["Color"])
    _tiles(bpy, m)
    _setup(bpy, scene)
    ours, theirs, report = _both(bpy, scene, tmp_path, "index")
    got = np.array([_at(ours, x, y) for x, y in TILES])
    want = np.array([_at(theirs, x, y) for x, y in TILES])
    np.testing.assert_allclose(got, want, atol=TILE_ATOL)
    expected = np.array([[(i + 1) / 10 + 0.025 * i, x + 1 + 0.25 * (1 - 0.1 * i), y + 1 + 0.125]
                         for i, (x, y) in enumerate(TILES)])
    np.testing.assert_allclose(got, expected, atol=TILE_ATOL)
    assert not [line for line in report if "IndexLocation" in line], report


def test_an_object_attribute_reads_a_custom_property_as_cycles(blender, empty_scene, tmp_path):
    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emissive(bpy, "CustomProperty")
    attr = nodes.new("ShaderNodeAttribute")
    attr.attribute_type, attr.attribute_name = "OBJECT", "tint"
    links.new(attr.outputs["Color"], emission.inputs["Color"])
    strength = nodes.new("ShaderNodeAttribute")  # a built-in path, through Fac
    strength.attribute_type, strength.attribute_name = "OBJECT", "pass_index"
    scale = nodes.new("ShaderNodeMath")
    scale.operation, scale.inputs[1].default_value = "MULTIPLY", 0.25
    links.new(strength.outputs["Fac"], scale.inputs[0])
    links.new(scale.outputs[0], emission.inputs["Strength"])
    tiles = _tiles(bpy, m, count=5)
    tiles[0]["tint"] = 0.5                 # a float: grey
    tiles[1]["tint"] = (1.0, 0.25, 0.0)    # a vector
    tiles[2]["tint"] = 2                   # an integer
    tiles[3].data["tint"] = (0.0, 0.5, 1.0, 1.0)  # on the mesh: found there
    # tiles[4] has none: black, as in Cycles
    _setup(bpy, scene)
    ours, theirs, report = _both(bpy, scene, tmp_path, "attribute")
    got = np.array([_at(ours, x, y) for x, y in TILES[:5]])
    want = np.array([_at(theirs, x, y) for x, y in TILES[:5]])
    np.testing.assert_allclose(got, want, atol=TILE_ATOL)
    np.testing.assert_allclose(got[0], [0.125] * 3, atol=TILE_ATOL)  # 0.5 x pass index 1 x 0.25
    np.testing.assert_allclose(got[4], [0, 0, 0], atol=TILE_ATOL)
    assert not [line for line in report if "CustomProperty" in line], report



def _light_path_sphere(bpy, scene, use_light_path=True, output="Is Camera Ray"):
    """A white floor under an emissive sphere: red where the Light Path `output` is 1 (Is
    Camera Ray: red to camera rays, green to all others), or red to every ray."""
    m, nodes, links, emission = _emissive(bpy, "RedToCamera")
    emission.inputs["Strength"].default_value = 4.0
    mix = nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    mix.inputs["A"].default_value = (0.0, 1.0, 0.0, 1.0)
    mix.inputs["B"].default_value = (1.0, 0.0, 0.0, 1.0)
    mix.inputs["Factor"].default_value = 1.0
    if use_light_path:
        path = nodes.new("ShaderNodeLightPath")
        links.new(path.outputs[output], mix.inputs["Factor"])
    links.new(mix.outputs["Result"], emission.inputs["Color"])
    plane(bpy, "Floor", 2.4, (0, 0, 0), principled(bpy, "White", base=(1.0, 1.0, 1.0)))
    uv_sphere(bpy, "Sphere", 0.25, (0, 0, 0.5), m)
    _setup(bpy, scene, samples=64)


def test_a_sphere_red_to_the_camera_lights_the_floor_green_as_in_cycles(blender, empty_scene, tmp_path):
    bpy, scene = blender, empty_scene
    _light_path_sphere(bpy, scene)
    ours, theirs, report = _both(bpy, scene, tmp_path, "light_path")
    # The sphere seen by the camera: red in both.
    np.testing.assert_allclose(_at(ours, 0, 0), [4, 0, 0], atol=TILE_ATOL)
    np.testing.assert_allclose(_at(theirs, 0, 0), [4, 0, 0], atol=TILE_ATOL)
    # The floor around it (a ring 0.35-1 m from the centre): lit green, as Cycles lights it.
    yy, xx = np.mgrid[:SIZE, :SIZE]
    r = np.hypot((xx + 0.5) / SIZE * 2.4 - 1.2, (yy + 0.5) / SIZE * 2.4 - 1.2)
    ring = (r > 0.35) & (r < 1.0)
    floor, cycles_floor = ours[ring].mean(0), theirs[ring].mean(0)
    np.testing.assert_allclose(floor[1], cycles_floor[1], rtol=FLOOR_RTOL)
    assert floor[0] < 0.02 * floor[1] and cycles_floor[0] < 0.02 * cycles_floor[1], (floor, cycles_floor)
    assert not [line for line in report if "RedToCamera" in line], report
    # Without the Light Path node the floor is lit red: outside the tolerance.
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "SPLAT_TRACER"
    _light_path_sphere(bpy, scene, use_light_path=False)
    wrong = render(bpy, scene, tmp_path / "red_everywhere.exr", (SIZE, SIZE))["ViewLayer"]["Combined"][..., :3]
    assert wrong[ring].mean(0)[1] < 0.1 * cycles_floor[1]


def _shadowless_block(bpy, scene, use_light_path=True):
    """A diffuse block over a white floor under a sun 30 degrees off the vertical; its
    material is transparent to shadow rays (Light Path > Is Shadow Ray into a Mix Shader of
    it and a Transparent BSDF), or an ordinary diffuse one."""
    m = principled(bpy, "NoShadow", base=(0.8, 0.2, 0.2))
    if use_light_path:
        nodes, links = m.node_tree.nodes, m.node_tree.links
        mix = nodes.new("ShaderNodeMixShader")
        path = nodes.new("ShaderNodeLightPath")
        transparent = nodes.new("ShaderNodeBsdfTransparent")
        links.new(path.outputs["Is Shadow Ray"], mix.inputs["Fac"])
        links.new(nodes["Principled BSDF"].outputs[0], mix.inputs[1])
        links.new(transparent.outputs[0], mix.inputs[2])
        links.new(mix.outputs[0], nodes["Material Output"].inputs["Surface"])
    plane(bpy, "Floor", 2.4, (0, 0, 0), principled(bpy, "White", base=(0.8, 0.8, 0.8)))
    cube(bpy, "Block", 0.4, (0, 0, 1), m)
    lamp(bpy, "SUN", rotation=(math.radians(30), 0, 0), energy=3.0)
    _setup(bpy, scene, samples=16)
    scene.cycles.transparent_max_bounces = 8  # Cycles walks shadow rays through transparency by these


def test_a_block_transparent_to_shadow_rays_casts_no_shadow_as_in_cycles(blender, empty_scene, tmp_path):
    bpy, scene = blender, empty_scene
    _shadowless_block(bpy, scene)
    ours, theirs, report = _both(bpy, scene, tmp_path, "no_shadow")
    # The block's shadow would fall 1 m x tan 30 = 0.58 m along +y (down the image).
    shadow = np.array([_at(ours, dx, 0.577 + dy) for dx in (-0.1, 0.1) for dy in (-0.1, 0.1)]).mean(0)
    cycles_shadow = np.array([_at(theirs, dx, 0.577 + dy) for dx in (-0.1, 0.1) for dy in (-0.1, 0.1)]).mean(0)
    open_floor = _at(ours, 0.8, -0.8)
    np.testing.assert_allclose(shadow, cycles_shadow, rtol=FLOOR_RTOL)
    np.testing.assert_allclose(shadow, open_floor, rtol=0.02)  # no shadow at all
    # The block itself is seen (opaque to the camera), in both.
    np.testing.assert_allclose(_at(ours, 0, 0), _at(theirs, 0, 0), rtol=FLOOR_RTOL)
    assert _at(ours, 0, 0)[0] > 2 * _at(ours, 0, 0)[1]
    # (The Mix Shader's blend is said, as for any Mix Shader; nothing of the Light Path.)
    assert not [line for line in report if "Light Path" in line], report
    # An ordinary block casts its shadow: far outside the tolerance.
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "SPLAT_TRACER"
    _shadowless_block(bpy, scene, use_light_path=False)
    wrong = render(bpy, scene, tmp_path / "shadowed.exr", (SIZE, SIZE))["ViewLayer"]["Combined"][..., :3]
    shadowed = np.array([_at(wrong, dx, 0.577 + dy) for dx in (-0.1, 0.1) for dy in (-0.1, 0.1)]).mean(0)
    assert shadowed.max() < 0.1 * cycles_shadow.max()


def test_a_lamp_tree_reads_light_path_as_cycles_evaluates_the_light_it_sends(blender, empty_scene, tmp_path):
    """Cycles evaluates a lamp's tree for the light it sends with no ray kind set: a Strength
    of 1 - Is Camera Ray lights the floor fully (read as a camera ray it would be dark)."""
    bpy, scene = blender, empty_scene
    plane(bpy, "Floor", 2.4, (0, 0, 0), principled(bpy, "White", base=(0.8, 0.8, 0.8)))
    sun = lamp(bpy, "SUN", energy=2.0)
    sun.data.use_nodes = True
    nodes, links = sun.data.node_tree.nodes, sun.data.node_tree.links
    path, invert = nodes.new("ShaderNodeLightPath"), nodes.new("ShaderNodeMath")
    invert.operation, invert.inputs[0].default_value = "SUBTRACT", 1.0
    links.new(path.outputs["Is Camera Ray"], invert.inputs[1])
    links.new(invert.outputs[0], nodes["Emission"].inputs["Strength"])
    _setup(bpy, scene)
    ours, theirs, report = _both(bpy, scene, tmp_path, "lamp_light_path")
    np.testing.assert_allclose(ours.mean((0, 1)), theirs.mean((0, 1)), rtol=0.02)
    assert ours.mean() > 0.3, ours.mean()  # 0.8 x 2 / pi: lit, not dark


def test_instancer_and_view_layer_attributes_match_cycles(blender, empty_scene, tmp_path):
    """Instancer: the instancing Empty's property first, else the object's own; View Layer:
    the view layer's, else the scene's. Colour = (instancer's, view layer's, 0)."""
    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emissive(bpy, "Instancer")
    by_instancer, by_layer = nodes.new("ShaderNodeAttribute"), nodes.new("ShaderNodeAttribute")
    by_instancer.attribute_type, by_instancer.attribute_name = "INSTANCER", "shade"
    by_layer.attribute_type, by_layer.attribute_name = "VIEW_LAYER", "level"
    comb = nodes.new("ShaderNodeCombineXYZ")
    links.new(by_instancer.outputs["Fac"], comb.inputs[0])
    links.new(by_layer.outputs["Fac"], comb.inputs[1])
    links.new(comb.outputs[0], emission.inputs["Color"])
    hidden = bpy.data.collections.new("Instanced")
    inner = _square(bpy, "InstancedTile", 0.5, (0, 0, 0), m, collection=hidden)
    inner["shade"] = 0.9  # read where no instancer has it
    for k, (x, y) in enumerate(TILES[:3]):
        empty = bpy.data.objects.new(f"Instancer{k}", None)
        empty.instance_type, empty.instance_collection = "COLLECTION", hidden
        empty.location = (x, y, 0)
        if k < 2:
            empty["shade"] = 0.2 + 0.3 * k
        scene.collection.objects.link(empty)
    plain = _square(bpy, "Plain", 0.5, TILES[3] + (0,), m)
    plain["shade"] = 0.4
    scene["level"] = 0.6
    _setup(bpy, scene)
    ours, theirs, report = _both(bpy, scene, tmp_path, "instancer")
    got = np.array([_at(ours, x, y) for x, y in TILES[:4]])
    want = np.array([_at(theirs, x, y) for x, y in TILES[:4]])
    np.testing.assert_allclose(got, want, atol=TILE_ATOL)
    np.testing.assert_allclose(got[:, 0], [0.2, 0.5, 0.9, 0.4], atol=TILE_ATOL)
    np.testing.assert_allclose(got[:, 1], 0.6, atol=TILE_ATOL)
    assert not [line for line in report if "Instancer" in line], report


def test_a_mirror_ray_is_glossy_singular_reflection_at_depth_one_as_in_cycles(blender, empty_scene, tmp_path):
    """An emissive ceiling behind the camera, seen only in a mirror floor: its colour says the
    ray that met it -- (Is Singular Ray, Ray Depth / 2, Is Reflection Ray / 4 + Is
    Transmission Ray) = (1, 0.5, 0.25) from a sharp mirror, as in Cycles."""
    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emissive(bpy, "Ceiling")
    path, comb = nodes.new("ShaderNodeLightPath"), nodes.new("ShaderNodeCombineXYZ")
    half, quarter = nodes.new("ShaderNodeMath"), nodes.new("ShaderNodeMath")
    half.operation, half.inputs[1].default_value = "MULTIPLY", 0.5
    quarter.operation, quarter.inputs[1].default_value = "MULTIPLY_ADD", 0.25
    links.new(path.outputs["Is Singular Ray"], comb.inputs[0])
    links.new(path.outputs["Ray Depth"], half.inputs[0])
    links.new(half.outputs[0], comb.inputs[1])
    links.new(path.outputs["Is Reflection Ray"], quarter.inputs[0])
    links.new(path.outputs["Is Transmission Ray"], quarter.inputs[2])
    links.new(quarter.outputs[0], comb.inputs[2])
    links.new(comb.outputs[0], emission.inputs["Color"])
    mirror = principled(bpy, "Mirror", base=(1.0, 1.0, 1.0), roughness=0.0, metallic=1.0)
    plane(bpy, "Floor", 2.4, (0, 0, 0), mirror)
    plane(bpy, "Ceiling", 4.0, (0, 0, 6), m)
    _setup(bpy, scene)
    c = scene.cycles
    c.max_bounces = c.glossy_bounces = 2
    ours, theirs, report = _both(bpy, scene, tmp_path, "mirror")
    np.testing.assert_allclose(_at(ours, 0, 0), _at(theirs, 0, 0), atol=TILE_ATOL)
    np.testing.assert_allclose(_at(ours, 0, 0), [1.0, 0.5, 0.25], atol=TILE_ATOL)


def test_object_info_random_of_geometry_nodes_instances_matches_cycles(blender, empty_scene, tmp_path):
    """A tile and Geometry Nodes' Instance on Points copies of it: each copy's Random is its own
    (Blender's per-instance id), as in Cycles."""
    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emissive(bpy, "RandomCopies")
    info = nodes.new("ShaderNodeObjectInfo")
    links.new(info.outputs["Random"], emission.inputs["Color"])
    tile = _square(bpy, "Tile", 0.5, TILES[0] + (0,), m)
    instance_with_geometry_nodes(bpy, tile, [p + (0,) for p in TILES[1:]])
    _setup(bpy, scene)
    ours, theirs, report = _both(bpy, scene, tmp_path, "gn_random")
    got = np.array([_at(ours, x, y) for x, y in TILES])
    want = np.array([_at(theirs, x, y) for x, y in TILES])
    np.testing.assert_allclose(got, want, atol=TILE_ATOL)
    assert got.max() > 0 and len(np.unique(np.round(got[:, 0], 3))) == len(TILES), got[:, 0]


def test_is_diffuse_ray_splits_a_sphere_light_between_sampling_and_bounces_as_in_cycles(blender, empty_scene,
                                                                                         tmp_path):
    """Is Diffuse Ray: green to light sampling (Cycles evaluates a sampled emitter with no ray
    kind), red to the diffuse rays that meet it; the floor gets both, weighed by multiple
    importance sampling. The sum matches Cycles; the split follows each engine's MIS weights
    (measured: red 0.029 / green 0.180 here, 0.017 / 0.193 in Cycles), so it is only
    required to be there in both."""
    bpy, scene = blender, empty_scene
    _light_path_sphere(bpy, scene, output="Is Diffuse Ray")
    c = scene.cycles
    c.max_bounces = c.diffuse_bounces = 1
    ours, theirs, report = _both(bpy, scene, tmp_path, "diffuse_ray")
    yy, xx = np.mgrid[:SIZE, :SIZE]
    r = np.hypot((xx + 0.5) / SIZE * 2.4 - 1.2, (yy + 0.5) / SIZE * 2.4 - 1.2)
    ring = (r > 0.35) & (r < 1.0)
    floor, cycles_floor = ours[ring].mean(0), theirs[ring].mean(0)
    np.testing.assert_allclose(floor.sum(), cycles_floor.sum(), rtol=FLOOR_RTOL)
    for f in (floor, cycles_floor):
        assert 0.05 * f[1] < f[0] < 0.5 * f[1], (floor, cycles_floor)
    assert not [line for line in report if "RedToCamera" in line], report


def test_material_index_and_alpha_match_cycles(blender, empty_scene, tmp_path):
    """Object Info's Material Index is the material's pass index, Alpha the object colour's."""
    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emissive(bpy, "MaterialIndex")
    m.pass_index = 4
    info, comb = nodes.new("ShaderNodeObjectInfo"), nodes.new("ShaderNodeCombineXYZ")
    tenth = nodes.new("ShaderNodeMath")
    tenth.operation, tenth.inputs[1].default_value = "MULTIPLY", 0.1
    links.new(info.outputs["Material Index"], tenth.inputs[0])
    links.new(tenth.outputs[0], comb.inputs[0])
    links.new(info.outputs["Alpha"], comb.inputs[1])
    links.new(comb.outputs[0], emission.inputs["Color"])
    tiles = _tiles(bpy, m, count=2)
    tiles[1].color = (1.0, 1.0, 1.0, 0.3)
    _setup(bpy, scene)
    ours, theirs, report = _both(bpy, scene, tmp_path, "material_index")
    got = np.array([_at(ours, x, y) for x, y in TILES[:2]])
    want = np.array([_at(theirs, x, y) for x, y in TILES[:2]])
    np.testing.assert_allclose(got, want, atol=TILE_ATOL)
    np.testing.assert_allclose(got, [[0.4, 1.0, 0.0], [0.4, 0.3, 0.0]], atol=TILE_ATOL)


def test_more_object_attributes_than_carried_are_said(blender, empty_scene, tmp_path):
    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emissive(bpy, "ManyProperties")
    total = None
    for k in range(17):
        attr = nodes.new("ShaderNodeAttribute")
        attr.attribute_type, attr.attribute_name = "OBJECT", f"p{k:02d}"
        if total is None:
            total = attr.outputs["Fac"]
            continue
        add = nodes.new("ShaderNodeMath")
        links.new(total, add.inputs[0])
        links.new(attr.outputs["Fac"], add.inputs[1])
        total = add.outputs[0]
    links.new(total, emission.inputs["Strength"])
    tile = _tiles(bpy, m, count=1)[0]
    for k in range(17):
        tile[f"p{k:02d}"] = 0.01
    _setup(bpy, scene)
    image = render(bpy, scene, tmp_path / "many.exr", (SIZE, SIZE))["ViewLayer"]["Combined"][..., :3]
    said = [line for line in stats()["report"] if "more than 16" in line]
    assert said == ["the materials read more than 16 object, instancer or view-layer attributes; these read 0: p16"]
    # The first 16 are read (the tile's colour is white x 16 x 0.01).
    np.testing.assert_allclose(_at(image, *TILES[0]), [0.16] * 3, atol=TILE_ATOL)


def test_sky_occlusion_rays_are_shadow_rays_to_a_light_path_node(blender, empty_scene, tmp_path):
    """Sky Light: Ambient Occlusion lights the floor by occlusion rays to the world: a block
    transparent to shadow rays (Light Path > Is Shadow Ray) lets them through, as every
    shadow ray. (They reached its program with no ray kind, read as a camera ray: blocked.)"""
    bpy = blender

    def floor_beside_block(use_light_path):
        bpy.ops.wm.read_homefile(use_empty=True)
        scene = bpy.context.scene
        scene.render.engine = "SPLAT_TRACER"
        _shadowless_block(bpy, scene, use_light_path)
        bpy.data.objects["Block"].location.z = 0.3  # low over the floor: it hides much of the sky
        bpy.data.objects.remove(next(o for o in bpy.data.objects if o.type == "LIGHT"))
        scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (1, 1, 1, 1)
        scene.cycles.max_bounces = scene.cycles.diffuse_bounces = 1
        scene.splat_tracer.sky_light, scene.cycles.samples = "AO", 64
        image = render(bpy, scene, tmp_path / f"sky_ao_{use_light_path}.exr", (SIZE, SIZE))["ViewLayer"]
        image = image["Combined"][..., :3]
        beside = np.array([_at(image, x, y) for x in (-0.3, 0.3) for y in (-0.3, 0.3)]).mean(0)
        return beside, _at(image, 0.9, -0.9)

    through, open_floor = floor_beside_block(True)
    np.testing.assert_allclose(through, open_floor, rtol=0.05)  # the block hides nothing
    blocked, open_floor = floor_beside_block(False)
    assert blocked.mean() < 0.9 * open_floor.mean(), (blocked, open_floor)  # an ordinary block does (0.86)
