"""Reading Blender materials, lamps, world, render settings and visibility into the plain
shading contract (real bpy), and the importer's "Splat Cloud" material."""
from __future__ import annotations

import math

import numpy as np
import pytest

from blender_helpers import add_camera, render_to_exr


@pytest.fixture
def es(blender):
    from splat_tracer.blender.export import shading as export_shading
    return export_shading


@pytest.fixture
def report():
    from splat_tracer.render import shading
    return shading.Report()


def approx(values, rel=1e-5, abs=1e-6):  # noqa: A002 - pytest's own names
    return pytest.approx(values, rel=rel, abs=abs)


def new_material(bpy, name, shader_type, **inputs):
    """A material whose Material Output is fed by one new shader node, with input values."""
    material = bpy.data.materials.new(name)
    nodes, links = material.node_tree.nodes, material.node_tree.links
    nodes.clear()
    shader = nodes.new(shader_type)
    output = nodes.new("ShaderNodeOutputMaterial")
    links.new(shader.outputs[0], output.inputs["Surface"])
    for key, value in inputs.items():
        shader.inputs[key].default_value = value
    return material, shader


# --------------------------------------------------------------------------------------
# Materials.

def test_principled_bsdf_maps_every_socket(blender, empty_scene, es, report):
    material, _ = new_material(blender, "Shiny", "ShaderNodeBsdfPrincipled", **{
        "Base Color": (0.2, 0.4, 0.6, 1.0), "Metallic": 0.3, "Roughness": 0.25, "IOR": 1.33,
        "Specular IOR Level": 0.7, "Transmission Weight": 0.4, "Alpha": 0.9,
        "Emission Color": (1.0, 0.5, 0.25, 1.0), "Emission Strength": 2.0})
    m = es.material_of(material, report)
    assert m.base_colour == approx((0.2, 0.4, 0.6))
    assert (m.metallic, m.roughness, m.ior, m.specular_level, m.transmission, m.alpha) == approx(
        (0.3, 0.25, 1.33, 0.7, 0.4, 0.9))
    assert m.emission == approx((2.0, 1.0, 0.5))
    assert not m.use_point_colour and not m.use_point_alpha
    assert report.lines == []


def test_principled_lobes_the_engine_ignores_are_reported(blender, empty_scene, es, report):
    material, _ = new_material(blender, "Car", "ShaderNodeBsdfPrincipled", **{"Coat Weight": 1.0,
                                                                              "Sheen Weight": 0.5})
    es.material_of(material, report)
    assert report.lines == ["material 'Car': the Principled BSDF's coat, sheen are ignored"]


@pytest.mark.parametrize("shader_type, inputs, expected", [
    ("ShaderNodeBsdfDiffuse", {"Color": (0.5, 0.25, 0.1, 1), "Roughness": 0.9},
     dict(base_colour=(0.5, 0.25, 0.1), specular_level=0.0, metallic=0.0, roughness=0.5)),
    ("ShaderNodeBsdfGlossy", {"Color": (0.9, 0.8, 0.7, 1), "Roughness": 0.1},
     dict(base_colour=(0.9, 0.8, 0.7), metallic=1.0, roughness=0.1)),
    ("ShaderNodeBsdfMetallic", {"Base Color": (0.9, 0.6, 0.3, 1), "Roughness": 0.2},
     dict(base_colour=(0.9, 0.6, 0.3), metallic=1.0, roughness=0.2)),
    ("ShaderNodeBsdfGlass", {"Color": (0.8, 1.0, 0.9, 1), "Roughness": 0.05, "IOR": 1.52},
     dict(base_colour=(0.8, 1.0, 0.9), transmission=1.0, ior=1.52, roughness=0.05, specular_level=0.5)),
    ("ShaderNodeBsdfRefraction", {"Color": (1, 1, 1, 1), "Roughness": 0.0, "IOR": 1.33},
     dict(base_colour=(1, 1, 1), transmission=1.0, ior=1.33, specular_level=0.0)),
    ("ShaderNodeEmission", {"Color": (1.0, 0.5, 0.0, 1), "Strength": 4.0},
     dict(base_colour=(0, 0, 0), emission=(4.0, 2.0, 0.0), specular_level=0.0)),
    ("ShaderNodeBsdfTransparent", {}, dict(alpha=0.0)),
])
def test_each_shader_node_maps_to_its_material(blender, empty_scene, es, report, shader_type, inputs, expected):
    material, _ = new_material(blender, "M", shader_type, **inputs)
    m = es.material_of(material, report)
    for key, value in expected.items():
        assert getattr(m, key) == approx(value), key
    assert report.lines == []


def test_point_colours_through_a_reroute_and_point_alpha(blender, empty_scene, es, report):
    material, principled = new_material(blender, "Scan", "ShaderNodeBsdfPrincipled")
    nodes, links = material.node_tree.nodes, material.node_tree.links
    attribute = nodes.new("ShaderNodeAttribute")
    attribute.attribute_name = "Col"  # a colour attribute's name: the points' own colours
    reroute = nodes.new("NodeReroute")
    links.new(attribute.outputs["Color"], reroute.inputs[0])
    links.new(reroute.outputs[0], principled.inputs["Base Color"])
    links.new(attribute.outputs["Alpha"], principled.inputs["Alpha"])
    m = es.material_of(material, report)
    assert m.use_point_colour and m.use_point_alpha and m.alpha == 1.0
    assert report.lines == []
    diffuse_material, diffuse = new_material(blender, "Painted", "ShaderNodeBsdfDiffuse")
    colour = diffuse_material.node_tree.nodes.new("ShaderNodeVertexColor")
    diffuse_material.node_tree.links.new(colour.outputs["Color"], diffuse.inputs["Color"])
    m = es.material_of(diffuse_material, report)
    assert m.use_point_colour and not m.use_point_alpha and report.lines == []


def test_an_object_attribute_is_not_a_point_colour(blender, empty_scene, es, report):
    material, principled = new_material(blender, "Tinted", "ShaderNodeBsdfPrincipled")
    attribute = material.node_tree.nodes.new("ShaderNodeAttribute")
    attribute.attribute_type, attribute.attribute_name = "OBJECT", "color"
    material.node_tree.links.new(attribute.outputs["Color"], principled.inputs["Base Color"])
    m = es.material_of(material, report)
    assert not m.use_point_colour
    assert m.program is not None and m.program.object_attributes == (("OBJECT", "color"),)
    assert report.lines == []


def test_an_unsupported_texture_falls_back_to_the_default_with_one_report_line(blender, empty_scene, es, report):
    material, principled = new_material(blender, "Floor", "ShaderNodeBsdfPrincipled")
    texture = material.node_tree.nodes.new("ShaderNodeParticleInfo")
    material.node_tree.links.new(texture.outputs["Velocity"], principled.inputs["Base Color"])
    m = es.material_of(material, report)
    es.material_of(material, report)  # the same material twice: still one line
    assert m.base_colour == approx((0.8, 0.8, 0.8)) and not m.use_point_colour
    assert report.lines == [
        "material 'Floor': the 'Particle Info' node is not supported; Base Color uses its unlinked value "
        "(0.8, 0.8, 0.8)"]


def test_what_a_bump_or_normal_map_cannot_read_is_said(blender, empty_scene, es, report):
    """A Bump's nearby points move the position-dependent globals only: a height from an
    attribute has no slope there, said; a Normal Map's own UV map is not read, said. A
    height from a texture says nothing."""
    material, principled = new_material(blender, "Bumpy", "ShaderNodeBsdfPrincipled")
    tree = material.node_tree
    bump, noise = tree.nodes.new("ShaderNodeBump"), tree.nodes.new("ShaderNodeTexNoise")
    tree.links.new(noise.outputs["Fac"], bump.inputs["Height"])
    tree.links.new(bump.outputs["Normal"], principled.inputs["Normal"])
    assert es.material_of(material, report).program is not None and report.lines == []
    attribute = tree.nodes.new("ShaderNodeAttribute")
    attribute.attribute_name = "height"
    tree.links.new(attribute.outputs["Fac"], bump.inputs["Height"])
    es.material_of(material, report)
    assert report.lines == ["material 'Bumpy': the Bump's height reads an attribute (an Attribute, Color Attribute "
                            "or named UV Map node, Pointiness, Random Per Island), which is not offset along the "
                            "surface: it adds no slope"]
    ao = tree.nodes.new("ShaderNodeAmbientOcclusion")
    tree.links.new(ao.outputs["AO"], bump.inputs["Height"])
    es.material_of(material, report)
    assert report.lines[1:] == ["material 'Bumpy': the Bump's height reads an Ambient Occlusion node (its rays "
                                "leave from the shading point), which is not offset along the surface: it adds "
                                "no slope"]
    del report.lines[1:]
    normal_map = tree.nodes.new("ShaderNodeNormalMap")
    normal_map.uv_map = "Second"
    tree.links.new(noise.outputs["Color"], normal_map.inputs["Color"])
    tree.links.new(normal_map.outputs["Normal"], principled.inputs["Normal"])
    es.material_of(material, report)
    assert report.lines[1:] == ["material 'Bumpy': the Normal Map's UV map 'Second' is not read; its tangents are "
                                "the active render UV map's"]


def test_an_image_texture_without_an_image_is_magenta_as_in_cycles(blender, empty_scene, es, report):
    material, principled = new_material(blender, "Floor", "ShaderNodeBsdfPrincipled")
    texture = material.node_tree.nodes.new("ShaderNodeTexImage")
    material.node_tree.links.new(texture.outputs["Color"], principled.inputs["Base Color"])
    m = es.material_of(material, report)
    assert m.program is not None and m.program.drives("base_colour")
    from splat_tracer.render import nodes
    regs = nodes.run(m.program)[0]
    base = m.program.outputs[0]
    assert tuple(regs[base:base + 3]) == (1.0, 0.0, 1.0)
    assert report.lines == ["material 'Floor': an Image Texture has no image; rendered magenta, as Cycles does"]


def test_a_diffuse_mixed_with_a_glossy_by_a_fresnel_keeps_the_lobes_apart_per_point(blender, empty_scene, es, report):
    """The classic material: the Fac a Fresnel's, per shading point. The program gives the
    diffuse's colour, the Glossy's own colour and roughness, metallic = the Fresnel."""
    from splat_tracer.render import nodes as program

    material = blender.data.materials.new("Classic")
    nodes, links = material.node_tree.nodes, material.node_tree.links
    nodes.clear()
    diffuse, glossy = nodes.new("ShaderNodeBsdfDiffuse"), nodes.new("ShaderNodeBsdfGlossy")
    diffuse.inputs["Color"].default_value = (1.0, 0.0, 0.0, 1.0)
    glossy.inputs["Color"].default_value = (0.0, 0.0, 1.0, 1.0)
    glossy.inputs["Roughness"].default_value = 0.2
    mix, output, fresnel = (nodes.new(t) for t in ("ShaderNodeMixShader", "ShaderNodeOutputMaterial",
                                                   "ShaderNodeFresnel"))
    fresnel.inputs["IOR"].default_value = 1.5
    links.new(fresnel.outputs["Fac"], mix.inputs[0])
    links.new(diffuse.outputs[0], mix.inputs[1])
    links.new(glossy.outputs[0], mix.inputs[2])
    links.new(mix.outputs[0], output.inputs["Surface"])
    m = es.material_of(material, report)
    for name in ("base_colour", "metal_colour", "metallic", "roughness", "specular_level"):
        assert m.program.drives(name) or getattr(m, name) is not None, name
    # Head-on (the view along the normal) and at 80 degrees: the dielectric Fresnel of IOR 1.5.
    cosines = np.array([1.0, math.cos(math.radians(80))])
    incoming = np.stack([np.sqrt(1 - cosines ** 2), np.zeros(2), cosines], axis=1)
    regs = program.run(m.program, n=2, N=(0, 0, 1), Ng=(0, 0, 1), I=incoming)

    def out(name, width):
        if not m.program.drives(name):
            return np.broadcast_to(np.asarray(getattr(m, name), float), (2, width))
        i = m.program.outputs[list(program.OUTPUTS).index(name)]
        return regs[:, i:i + width]

    def fresnel_dielectric(c, eta):  # the exact dielectric Fresnel, unpolarised
        g = np.sqrt(eta ** 2 - 1 + c ** 2)
        return 0.5 * ((g - c) / (g + c)) ** 2 * (1 + ((c * (g + c) - 1) / (c * (g - c) + 1)) ** 2)

    assert out("metallic", 1)[:, 0] == approx(fresnel_dielectric(cosines, 1.5), rel=1e-4)
    assert out("base_colour", 3) == approx(np.array([[1.0, 0.0, 0.0]] * 2), rel=1e-5)
    assert out("metal_colour", 3) == approx(np.array([[0.0, 0.0, 1.0]] * 2), rel=1e-5)
    assert out("roughness", 1)[:, 0] == approx([0.2, 0.2], rel=1e-5)
    assert out("specular_level", 1)[:, 0] == approx([0.0, 0.0])


def test_mix_shader_blends_the_parameters_and_reports_once(blender, empty_scene, es, report):
    material = blender.data.materials.new("Blend")
    nodes, links = material.node_tree.nodes, material.node_tree.links
    nodes.clear()
    diffuse, glossy = nodes.new("ShaderNodeBsdfDiffuse"), nodes.new("ShaderNodeBsdfGlossy")
    diffuse.inputs["Color"].default_value = (1.0, 0.0, 0.0, 1.0)
    glossy.inputs["Color"].default_value = (0.0, 0.0, 1.0, 1.0)
    glossy.inputs["Roughness"].default_value = 0.2
    mix, output = nodes.new("ShaderNodeMixShader"), nodes.new("ShaderNodeOutputMaterial")
    mix.inputs[0].default_value = 0.25
    links.new(diffuse.outputs[0], mix.inputs[1])
    links.new(glossy.outputs[0], mix.inputs[2])
    links.new(mix.outputs[0], output.inputs["Surface"])
    m = es.material_of(material, report)
    # The two closures' lobes kept apart: the diffuse share of its colour, without specular,
    # the glossy share (metallic) of the Glossy's colour and roughness.
    assert m.base_colour == approx((1.0, 0.0, 0.0)) and m.metal_colour == approx((0.0, 0.0, 1.0))
    assert m.metallic == approx(0.25)  # the glossy share
    assert m.roughness == approx(0.2)
    assert m.specular_level == 0.0
    assert report.lines == ["material 'Blend': Mix and Add Shaders are approximated by blending their shaders' "
                            "parameters"]
    # Transparent mixed in: alpha is the opaque share, the surface colour stays the BSDF's.
    transparent = nodes.new("ShaderNodeBsdfTransparent")
    links.new(transparent.outputs[0], mix.inputs[2])
    m = es.material_of(material, report)
    assert m.alpha == approx(0.75) and m.base_colour == approx((1.0, 0.0, 0.0)) and m.metal_colour is None
    assert len(report.lines) == 1
    # Add Shader: emission adds to the surface, which stays whole.
    emission, add = nodes.new("ShaderNodeEmission"), nodes.new("ShaderNodeAddShader")
    emission.inputs["Strength"].default_value = 3.0
    links.new(diffuse.outputs[0], add.inputs[0])
    links.new(emission.outputs[0], add.inputs[1])
    links.new(add.outputs[0], output.inputs["Surface"])
    m = es.material_of(material, report)
    assert m.base_colour == approx((1.0, 0.0, 0.0)) and m.emission == approx((3.0, 3.0, 3.0)) and m.alpha == 1.0


def test_material_without_nodes(blender, empty_scene, es, report):
    bpy = blender
    material = bpy.data.materials.new("Legacy")
    material.diffuse_color, material.metallic, material.roughness = (0.1, 0.6, 0.3, 1.0), 0.2, 0.7
    if bpy.app.version >= (5, 0, 0):
        # Blender 5 has no node-less materials: use_nodes is deprecated and stays on, and
        # the nodes are read (a new material's default Principled BSDF).
        material.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.9, 0.9, 0.2, 1.0)
        with pytest.deprecated_call():
            material.use_nodes = False
        m = es.material_of(material, report)
        assert m.base_colour == approx((0.9, 0.9, 0.2)) and report.lines == []
    else:
        material.use_nodes = False
        m = es.material_of(material, report)
        assert m.base_colour == approx((0.1, 0.6, 0.3)) and (m.metallic, m.roughness) == approx((0.2, 0.7))
        assert report.lines == ["material 'Legacy' does not use nodes; using its viewport display colour, "
                                "metallic and roughness"]


def test_the_cycles_output_is_read_where_outputs_differ_per_engine(blender, empty_scene, es, report):
    """What Blender 5 makes of a node-less material from an older file: an active EEVEE
    output with a Principled BSDF and an inactive Cycles one with a Diffuse BSDF."""
    material, principled = new_material(blender, "Versioned", "ShaderNodeBsdfPrincipled")
    nodes = material.node_tree.nodes
    eevee = next(n for n in nodes if n.type == "OUTPUT_MATERIAL")
    eevee.target = "EEVEE"
    diffuse, cycles = nodes.new("ShaderNodeBsdfDiffuse"), nodes.new("ShaderNodeOutputMaterial")
    cycles.target = "CYCLES"
    diffuse.inputs["Color"].default_value = (0.3, 0.2, 0.1, 1.0)
    material.node_tree.links.new(diffuse.outputs[0], cycles.inputs["Surface"])
    eevee.is_active_output = True
    assert not cycles.is_active_output
    m = es.material_of(material, report)
    assert m.base_colour == approx((0.3, 0.2, 0.1)) and m.specular_level == 0.0


def test_no_material_no_output_and_ignored_outputs(blender, empty_scene, es, report):
    from splat_tracer.render import shading
    assert es.material_of(None, report) == shading.Material() and report.lines == []
    empty = blender.data.materials.new("Empty")
    empty.node_tree.nodes.clear()
    m = es.material_of(empty, report)
    assert m.base_colour == (0, 0, 0) and m.specular_level == 0  # black, as Cycles renders it
    assert report.lines == ["material 'Empty' has no Material Output; rendered black, as Cycles does"]
    material, _ = new_material(blender, "Foggy", "ShaderNodeBsdfDiffuse")
    nodes, links = material.node_tree.nodes, material.node_tree.links
    output = next(n for n in nodes if n.type == "OUTPUT_MATERIAL")
    links.new(nodes.new("ShaderNodeVolumePrincipled").outputs[0], output.inputs["Volume"])
    links.new(nodes.new("ShaderNodeDisplacement").outputs[0], output.inputs["Displacement"])
    es.material_of(material, report)
    assert report.lines[-1] == "material 'Foggy': Volume, Displacement are ignored"


def test_a_volume_only_material_is_transparent_and_said(blender, empty_scene, es, report):
    """Only a Volume into the Material Output: the volume is not rendered, so the surface is
    absent (alpha 0), said once -- not a black box, and no claim that Cycles renders it so."""
    material, _ = new_material(blender, "Fog", "ShaderNodeBsdfDiffuse")
    nodes, links = material.node_tree.nodes, material.node_tree.links
    output = next(n for n in nodes if n.type == "OUTPUT_MATERIAL")
    links.remove(output.inputs["Surface"].links[0])
    links.new(nodes.new("ShaderNodeVolumePrincipled").outputs[0], output.inputs["Volume"])
    m = es.material_of(material, report)
    assert m.alpha == 0.0 and m.emission == (0, 0, 0)
    assert report.lines == ["material 'Fog': only a Volume shader is connected; the volume is not rendered, "
                            "the object is transparent"]


# --------------------------------------------------------------------------------------
# Lamps.

def add_lamp(bpy, scene, kind, location=(0, 0, 0), rotation=(0, 0, 0), scale=(1, 1, 1), **settings):
    light = bpy.data.lights.new(kind.title(), kind)
    for key, value in settings.items():
        setattr(light, key, value)
    obj = bpy.data.objects.new(kind.title(), light)
    scene.collection.objects.link(obj)
    obj.location, obj.rotation_euler, obj.scale = location, rotation, scale
    bpy.context.view_layer.update()
    return obj


def lamp_of(bpy, es, obj, report):
    obj_eval = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    return es.light_of(obj_eval, np.array(obj_eval.matrix_world, np.float64), report)


def test_point_spot_and_sun_lamps(blender, empty_scene, es, report):
    bpy = blender
    point = add_lamp(bpy, empty_scene, "POINT", location=(1, 2, 3), energy=250.0, shadow_soft_size=0.2,
                     color=(1.0, 0.5, 0.25), use_shadow=False, use_soft_falloff=False)
    p = lamp_of(bpy, es, point, report)
    assert (p.type, p.power, p.radius, p.cast_shadow, p.soft_falloff) == ("POINT", 250.0, approx(0.2), False, False)
    assert p.position == approx((1, 2, 3)) and p.colour == approx((1.0, 0.5, 0.25))
    # Rotated 90 degrees about X: local -Z points along world +Y.
    spot = add_lamp(bpy, empty_scene, "SPOT", rotation=(math.pi / 2, 0, 0), energy=80.0,
                    spot_size=math.radians(30), spot_blend=0.4)
    s = lamp_of(bpy, es, spot, report)
    assert s.direction == approx((0, 1, 0)) and s.u_axis == approx((1, 0, 0))
    assert (s.spot_size, s.spot_blend, s.power) == approx((math.radians(30), 0.4, 80.0))
    sun = add_lamp(bpy, empty_scene, "SUN", energy=3.5, angle=math.radians(2))
    u = lamp_of(bpy, es, sun, report)
    assert (u.type, u.power, u.angle) == ("SUN", approx(3.5), approx(math.radians(2)))
    assert u.direction == approx((0, 0, -1))
    assert report.lines == []
    camera = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    assert es.light_of(camera, np.eye(4), report) is None


def test_rotated_scaled_area_lamp(blender, empty_scene, es, report):
    bpy = blender
    area = add_lamp(bpy, empty_scene, "AREA", location=(0, 0, 4), rotation=(0, 0, math.pi / 2), scale=(2, 3, 1),
                    shape="RECTANGLE", size=1.5, size_y=0.5, energy=400.0)
    a = lamp_of(bpy, es, area, report)
    assert (a.shape, a.size, a.size_y, a.power) == ("RECTANGLE", approx(3.0), approx(1.5), 400.0)
    assert not a.soft_falloff  # a Blender option of point and spot lamps only
    assert a.u_axis == approx((0, 1, 0)) and a.direction == approx((0, 0, -1)) and a.position == approx((0, 0, 4))
    # A square stretched unevenly is a rectangle (the contract packs one size for squares).
    square = add_lamp(bpy, empty_scene, "AREA", scale=(1, 2, 1), shape="DISK", size=1.0)
    d = lamp_of(bpy, es, square, report)
    assert (d.shape, d.size, d.size_y) == ("ELLIPSE", approx(1.0), approx(2.0))
    assert report.lines == []
    narrow = add_lamp(bpy, empty_scene, "AREA", spread=math.radians(30))
    lamp_of(bpy, es, narrow, report)
    assert report.lines == ["light 'Area.002': a spread of 30 degrees is ignored (rendered as 180)"]


def _lamp_tree(bpy, scene, kind="POINT", **settings):
    """A lamp with a node tree of its own: (object, its nodes, its links, its Emission)."""
    obj = add_lamp(bpy, scene, kind, use_nodes=True, **settings)
    obj.data = obj.data.copy()
    tree = obj.data.node_tree
    return obj, tree.nodes, tree.links, next(n for n in tree.nodes if n.type == "EMISSION")


def test_lamp_node_trees_are_evaluated_once(blender, empty_scene, es, report):
    """The Emission's Color x Strength from constant nodes multiplies the lamp's colour:
    Blackbody (its colour, the unit tests' definition) times a Math chain; the default tree
    changes nothing; light linking is still said."""
    bpy = blender
    plain = add_lamp(bpy, empty_scene, "POINT", use_nodes=True)  # the default Emission: nothing to say
    assert lamp_of(bpy, es, plain, report).colour == approx((1, 1, 1)) and report.lines == []
    halved, _, _, emission = _lamp_tree(bpy, empty_scene)
    emission.inputs["Strength"].default_value = 0.5
    assert lamp_of(bpy, es, halved, report).colour == approx((0.5, 0.5, 0.5))
    warm, nodes_, links, emission = _lamp_tree(bpy, empty_scene, color=(1.0, 0.5, 1.0))
    blackbody, value, math_ = (nodes_.new(t) for t in ("ShaderNodeBlackbody", "ShaderNodeValue", "ShaderNodeMath"))
    blackbody.inputs["Temperature"].default_value = 3315.0
    value.outputs[0].default_value = 1.5
    math_.operation = "MULTIPLY"
    math_.inputs[1].default_value = 2.0
    links.new(blackbody.outputs["Color"], emission.inputs["Color"])
    links.new(value.outputs[0], math_.inputs[0])
    links.new(math_.outputs[0], emission.inputs["Strength"])
    from splat_tracer.render import nodes as programs
    b = programs.Builder()
    out = b.register(width=3)
    b.emit("BLACKBODY", out, b.register(3315.0))
    bb = programs.run(b.program())[0, out:out + 3]
    assert lamp_of(bpy, es, warm, report).colour == approx(tuple(np.array([1.0, 0.5, 1.0]) * bb * 3.0), rel=1e-5)
    # Blender's own blackbody colour there, within the Blackbody node's stated 1 %.
    assert lamp_of(bpy, es, warm, report).colour == approx((1.631801 * 3, 0.877736 * 1.5, 0.355867 * 3), rel=0.01)
    linked = add_lamp(bpy, empty_scene, "SPOT")
    linked.light_linking.receiver_collection = bpy.data.collections.new("Receivers")
    lamp_of(bpy, es, linked, report)
    assert report.lines == [f"light '{linked.name}': light linking is ignored"]
    # A node that reads a surface: the tree runs at the lamp's centre with none, said.
    shaded, nodes_, links, emission = _lamp_tree(bpy, empty_scene)
    ao = nodes_.new("ShaderNodeAmbientOcclusion")
    links.new(ao.outputs["AO"], emission.inputs["Strength"])
    lamp_of(bpy, es, shaded, report)
    assert f"light '{shaded.name}': its node tree is evaluated with no surface: Ambient Occlusion reads 1" \
        in report.lines[1:], report.lines


def test_blackbody_node_beside_blenders_own(blender, empty_scene):
    """The Blackbody node's colour against Blender's own blackbody (a lamp's
    temperature_color with Temperature on: the colour Cycles' Blackbody node gives), read
    live: within 1 % per channel from 3000 K up, 2 % (0.002 absolute) at 2000 K."""
    from splat_tracer.render import nodes as programs
    light = add_lamp(blender, empty_scene, "POINT", use_temperature=True).data
    for kelvin, rtol, atol in ((2000, 0.021, 0.002), (3000, 0.01, 1e-3), (4500, 0.01, 1e-3), (6500, 0.01, 1e-3),
                               (9000, 0.01, 1e-3), (12000, 0.01, 1e-3), (16000, 0.01, 1e-3)):
        light.temperature = kelvin
        b = programs.Builder()
        out = b.register(width=3)
        b.emit("BLACKBODY", out, b.register(float(kelvin)))
        got = programs.run(b.program())[0, out:out + 3]
        np.testing.assert_allclose(got, light.temperature_color[:3], rtol=rtol, atol=atol, err_msg=str(kelvin))


def test_lamp_node_trees_that_vary_or_are_not_emission_are_said(blender, empty_scene, es, report):
    """A texture in the lamp's tree is read once, at the lamp's centre (said); a tree whose
    output is not an Emission shader is ignored (said)."""
    bpy = blender
    textured, nodes_, links, emission = _lamp_tree(bpy, empty_scene, location=(1.5, 0, 0))
    checker, coords = nodes_.new("ShaderNodeTexChecker"), nodes_.new("ShaderNodeTexCoord")
    checker.inputs["Color1"].default_value = (1, 0, 0, 1)
    checker.inputs["Color2"].default_value = (0, 0, 1, 1)
    checker.inputs["Scale"].default_value = 1.0
    links.new(coords.outputs["Object"], checker.inputs["Vector"])
    links.new(checker.outputs["Color"], emission.inputs["Color"])
    # The lamp's centre is its own space's origin: Color2 there (the scene's x = 1.5 would give Color1).
    assert lamp_of(bpy, es, textured, report).colour == approx((0, 0, 1))
    assert report.lines == [f"light '{textured.name}': its node tree varies over the lamp (object); "
                            f"its colour at the lamp's centre is used"]
    report.lines.clear()
    other, nodes_, links, emission = _lamp_tree(bpy, empty_scene)
    output = next(n for n in nodes_ if n.type == "OUTPUT_LIGHT")
    links.new(nodes_.new("ShaderNodeBsdfDiffuse").outputs[0], output.inputs["Surface"])
    assert lamp_of(bpy, es, other, report).colour == approx((1, 1, 1))
    assert report.lines == [f"light '{other.name}': its node tree is ignored (only an Emission shader into the "
                            f"Light Output is read)"]


# --------------------------------------------------------------------------------------
# World.

def test_world_background_colour_strength_and_film(blender, empty_scene, es, report):
    bpy = blender
    scene = empty_scene
    scene.world = None
    scene.render.film_transparent = True
    w = es.world_of(scene, report)
    assert w.radiance() == (0, 0, 0) and w.transparent
    scene.world = bpy.data.worlds.new("Sky")
    background = scene.world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (0.2, 0.3, 0.4, 1.0)
    background.inputs["Strength"].default_value = 2.5
    scene.render.film_transparent = False
    w = es.world_of(scene, report)
    assert w.colour == approx((0.2, 0.3, 0.4)) and w.strength == approx(2.5) and not w.transparent
    assert report.lines == []


def test_world_without_nodes(blender, empty_scene, es, report):
    bpy = blender
    world = empty_scene.world = bpy.data.worlds.new("Plain")
    world.color = (0.1, 0.2, 0.3)
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.5, 0.5, 0.5, 1.0)
    if bpy.app.version >= (5, 0, 0):  # use_nodes is deprecated and stays on: nodes are read
        with pytest.deprecated_call():
            world.use_nodes = False
        assert es.world_of(empty_scene, report).colour == approx((0.5, 0.5, 0.5))
    else:
        world.use_nodes = False
        assert es.world_of(empty_scene, report).colour == approx((0.1, 0.2, 0.3))
    assert report.lines == []


def test_world_textures_fall_back_and_are_reported(blender, empty_scene, es, report):
    bpy = blender
    world = empty_scene.world = bpy.data.worlds.new("Outdoor")
    nodes, links = world.node_tree.nodes, world.node_tree.links
    background = nodes["Background"]
    background.inputs["Strength"].default_value = 0.5
    sky = nodes.new("ShaderNodeTexSky")
    links.new(sky.outputs["Color"], background.inputs["Color"])
    w = es.world_of(empty_scene, report)
    # The Sky Texture is baked from its model (render/sky.py; compared with Cycles in
    # test_world_environment.py) x strength: the default sky (Multiple Scattering, sun 15
    # degrees up) at the zenith and straight down; its sun, smaller than the bake's pixels,
    # spread over them, said once.
    assert w.environment is not None and w.environment[-1, 0] == approx((0.310, 0.633, 1.328), rel=0.01)
    assert w.environment[0, 0] == approx((0.00715, 0.0111, 0.0201), rel=0.01)
    assert len(report.lines) == 1 and "sun disc (0.55 degrees) is smaller than 2 pixels" in report.lines[0]
    background.inputs["Color"].default_value = (0.3, 0.3, 0.3, 1.0)
    # An Environment Texture is baked (tests/blender/test_world_environment.py); without an
    # image, Cycles renders its missing-image pink (measured: (1.02, 0.0004, 1.04) on 8x8
    # pixels), a uniform world: the uniform path, x strength, nothing to report.
    links.new(nodes.new("ShaderNodeTexEnvironment").outputs["Color"], background.inputs["Color"])
    w = es.world_of(empty_scene, report)
    assert w.environment is None and w.radiance() == approx((0.5, 0.0, 0.5))
    assert len(report.lines) == 1
    # A node the engine does not evaluate falls back to the socket's default value, said once
    # (the Environment Texture left unconnected: nothing is baked).
    links.new(nodes.new("ShaderNodeTexNoise").outputs["Color"], background.inputs["Color"])
    w = es.world_of(empty_scene, report)
    assert w.environment is None and w.radiance() == approx((0.15, 0.15, 0.15))
    assert report.lines[1] == ("world 'Outdoor': Color is driven by a 'Noise Texture' node; "
                               "using its default value (0.3, 0.3, 0.3)")


# --------------------------------------------------------------------------------------
# Render settings and visibility.

def test_render_settings_from_the_scene_and_cycles(blender, empty_scene, es):
    scene = empty_scene
    s = es.render_settings_of(scene)
    assert (s.samples, s.shadow_samples) == (scene.cycles.samples, 1)  # Cycles' Samples
    scene.cycles.samples, scene.splat_tracer.shadow_samples = 64, 4
    scene.render.filter_size = 2.0
    cycles = scene.cycles
    cycles.pixel_filter_type = "GAUSSIAN"
    cycles.max_bounces, cycles.diffuse_bounces, cycles.glossy_bounces = 6, 2, 3
    cycles.transmission_bounces, cycles.transparent_max_bounces, cycles.seed = 5, 7, 42
    s = es.render_settings_of(scene)
    assert (s.samples, s.shadow_samples, s.pixel_filter, s.filter_width) == (64, 4, "GAUSSIAN", 2.0)
    assert (s.max_bounces, s.diffuse_bounces, s.glossy_bounces, s.transmission_bounces,
            s.transparent_bounces, s.seed) == (6, 2, 3, 5, 7, 42)
    cycles.use_animated_seed = True
    seeds = set()
    for frame in (1, 2):
        scene.frame_set(frame)
        seeds.add(es.render_settings_of(scene).seed)
    assert len(seeds) == 2  # the noise changes from frame to frame


def test_visibility_flags_and_holdout(blender, empty_scene, es):
    bpy = blender
    scene = empty_scene
    collection = bpy.data.collections.new("Held")
    scene.collection.children.link(collection)
    obj = bpy.data.objects.new("Thing", bpy.data.meshes.new("Thing"))
    collection.objects.link(obj)
    obj.visible_glossy, obj.visible_shadow = False, False
    view_layer = bpy.context.view_layer

    def flags():
        depsgraph = bpy.context.evaluated_depsgraph_get()
        evaluated = obj.evaluated_get(depsgraph)
        from_eval = es.object_visibility(evaluated, depsgraph.view_layer_eval)
        assert es.object_visibility(evaluated, view_layer) == from_eval  # either view layer works
        assert es.object_visibility(obj, view_layer) == from_eval
        return from_eval

    assert flags() == dict(camera=True, diffuse=True, glossy=False, transmission=True, shadow=False, holdout=False,
                           shadow_catcher=False)
    view_layer.layer_collection.children["Held"].holdout = True
    assert flags()["holdout"]
    view_layer.layer_collection.children["Held"].holdout = False
    assert not flags()["holdout"]
    obj.is_holdout = True
    assert flags()["holdout"]
    obj.is_holdout = False
    parent = bpy.data.objects.new("Parent", None)
    parent.visible_camera = False
    parent.is_holdout = True
    instanced = es.object_visibility(obj, view_layer, parent=parent)
    assert not instanced["camera"] and instanced["holdout"] and instanced["diffuse"]


def test_sampling_settings_are_registered(blender):
    bpy = blender
    assert hasattr(bpy.types, "SPLAT_TRACER_PT_sampling") and hasattr(bpy.types, "SPLAT_TRACER_PT_light_paths")
    samples = bpy.types.Scene.bl_rna.properties["splat_tracer"].fixed_type.properties["samples"]
    assert (samples.default, samples.hard_min, samples.soft_max) == (16, 1, 1024)


# --------------------------------------------------------------------------------------
# The importer's material.

def grid_cloud(n=21):
    g = np.stack(np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n)), -1).reshape(-1, 2)
    positions = np.column_stack([g, np.zeros(len(g))])
    return positions, np.tile([0.0, 0.0, 1.0], (len(g), 1)), np.full(len(g), 0.08)


def cloud_materials(bpy, obj):
    depsgraph = bpy.context.evaluated_depsgraph_get()
    cloud = next(i.object for i in depsgraph.object_instances
                 if i.object.type == "POINTCLOUD" and i.object.original == obj)
    return [m.name for m in cloud.data.materials]


def test_imported_clouds_show_their_colours_in_cycles(blender, empty_scene, es, report, tmp_path):
    bpy = blender
    from splat_tracer.blender import cloud_object
    scene = empty_scene
    positions, normals, radii = grid_cloud()
    red = np.tile([0.9, 0.1, 0.05, 1.0], (len(positions), 1))
    coloured = cloud_object.create_cloud_object("Coloured", positions, normals, radii, red, location=(-1.2, 0, 0))
    plain = cloud_object.create_cloud_object("Plain", positions, normals, radii, None, location=(1.2, 0, 0))
    assert cloud_materials(bpy, coloured) == ["Splat Cloud"]
    assert cloud_materials(bpy, plain) == []  # Cycles would shade a missing attribute black
    material = bpy.data.materials["Splat Cloud"]
    m = es.material_of(material, report)
    assert m.use_point_colour and report.lines == []
    cloud_object.create_cloud_object("Again", positions, normals, radii, red)
    assert len([m for m in bpy.data.materials if m.get(cloud_object.MATERIAL_TAG)]) == 1  # created once

    add_camera(bpy, scene, (0, 0, 6), (0, 0, 0), type="ORTHO", ortho_scale=5.0)
    bpy.data.objects.remove(bpy.data.objects["Again"])
    scene.world = bpy.data.worlds.new("White")
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (1, 1, 1, 1)
    scene.render.engine = "CYCLES"
    scene.cycles.samples, scene.cycles.device = 4, "CPU"
    out = render_to_exr(bpy, scene, tmp_path / "cycles.exr", 32, 32, passes=False)["rgba"]
    left, right = out[16, 8, :3], out[16, 24, :3]
    # Lit by a white sky: the coloured cloud shows its red, the plain one Cycles' grey.
    assert left[0] > 0.6 and left[1] < 0.25 * left[0] and left[2] < 0.25 * left[0]
    assert right == approx([0.8, 0.8, 0.8], rel=0.1)


def test_a_file_with_the_version_1_node_group_still_renders(blender, empty_scene, tmp_path):
    bpy = blender
    from splat_tracer.blender import cloud_object
    scene = empty_scene
    positions, normals, radii = grid_cloud()
    colours = np.tile([0.2, 0.9, 0.1, 1.0], (len(positions), 1))
    obj = cloud_object.create_cloud_object("Old", positions, normals, radii, colours)
    # The group as version 1 made it: Mesh to Points only.
    group = bpy.data.node_groups.new("Splat Points", "GeometryNodeTree")
    group[cloud_object.NODE_GROUP_TAG] = 1
    group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    inp, out, to_points = (group.nodes.new(t) for t in ("NodeGroupInput", "NodeGroupOutput",
                                                        "GeometryNodeMeshToPoints"))
    radius = group.nodes.new("GeometryNodeInputNamedAttribute")
    radius.inputs["Name"].default_value = cloud_object.RADIUS
    group.links.new(inp.outputs[0], to_points.inputs["Mesh"])
    group.links.new(radius.outputs["Attribute"], to_points.inputs["Radius"])
    group.links.new(to_points.outputs["Points"], out.inputs[0])
    obj.modifiers[0].node_group = group
    for other in [g for g in bpy.data.node_groups if g != group]:
        bpy.data.node_groups.remove(other)
    path = tmp_path / "version1.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.open_mainfile(filepath=str(path))
    scene = bpy.context.scene
    assert [g.get(cloud_object.NODE_GROUP_TAG) for g in bpy.data.node_groups] == [1]
    add_camera(bpy, scene, (0, 0, 6), (0, 0, 0), type="ORTHO", ortho_scale=3.0)
    pixel = render_to_exr(bpy, scene, tmp_path / "old.exr", 32, 32)["rgba"][16, 16]
    assert pixel[3] == 1.0 and pixel[1] > 2 * pixel[0]  # the points' green, headlit
    new = cloud_object.create_cloud_object("New", positions, normals, radii, colours)
    assert new.modifiers[0].node_group[cloud_object.NODE_GROUP_TAG] == cloud_object.NODE_GROUP_VERSION
