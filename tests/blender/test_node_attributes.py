"""The Attribute node reading a scan's own attributes (issue 24, item 1) side by side with Cycles.

A flat cloud (the importer's object, 37 x 37 points) whose `intensity` is 0.2 on its left half
and 0.8 on its right, and whose `classification` is the other way round, emits the colour an
Attribute node -> Color Ramp gives. The scene and its tolerance are test_node_materials.py's:
orthographic view straight down, 80x80 px, 16 samples; an Emission shader, not Base Color under
a lamp, because Cycles renders points as spheres (their shading over a sphere is not a disc's),
while the emitted colour is the attribute's through the ramp in both.
- COLOUR_RTOL = 0.05 (atol 0.01): the mean colour per half against Cycles' and against the ramp
  computed here; reading the wrong attribute (classification) is outside it.
A lit mesh floor with a float attribute on its vertices, faces or face corners feeds Base Color
the same way (measured: equal to Cycles' within 1e-5 per half).
"""
from __future__ import annotations

import numpy as np
import pytest

from test_node_materials import COLOUR_RTOL, _both, _setup

RAMP = ((0.0, 0.1, 0.9), (1.0, 0.8, 0.0))  # the ramp's two stops' colours, at 0 and 1
INTENSITY = (0.2, 0.8)  # left and right halves
CLASSIFICATION = (0.9, 0.1)


def _ramp(t):
    return np.add(np.multiply(1 - t, RAMP[0]), np.multiply(t, RAMP[1]))


def _cloud(bpy, material, with_attributes=True, extra=None):
    from splat_tracer.blender import cloud_object

    g = np.stack(np.meshgrid(np.linspace(-0.9, 0.9, 37), np.linspace(-0.9, 0.9, 37)), -1).reshape(-1, 2)
    left = g[:, 0] < 0
    attributes = {"intensity": np.where(left, *INTENSITY).astype(np.float32),
                  "classification": np.where(left, *CLASSIFICATION).astype(np.float32)}
    attributes.update({name: np.full(len(g), value, np.float32) for name, value in (extra or {}).items()})
    obj = cloud_object.create_cloud_object("Scan", np.column_stack([g, np.zeros(len(g))]),
                                           np.tile([0.0, 0.0, 1.0], (len(g), 1)), np.full(len(g), 0.05),
                                           np.full((len(g), 4), 0.5),  # the importer sets the material on coloured clouds
                                           attributes=attributes if with_attributes else None)
    for modifier in obj.modifiers:  # the importer's Set Material: this material instead
        for node in modifier.node_group.nodes if modifier.type == "NODES" else ():
            if node.bl_idname == "GeometryNodeSetMaterial":
                node.inputs["Material"].default_value = material
    return obj


def _ramped(bpy, name, output="Fac"):
    m = bpy.data.materials.new("Ramped")
    nodes, links = m.node_tree.nodes, m.node_tree.links
    nodes.remove(nodes["Principled BSDF"])
    emission, attribute, ramp = (nodes.new(t) for t in ("ShaderNodeEmission", "ShaderNodeAttribute",
                                                         "ShaderNodeValToRGB"))
    attribute.attribute_name = name
    for element, colour in zip(ramp.color_ramp.elements, RAMP):
        element.color = (*colour, 1.0)
    links.new(attribute.outputs[output], ramp.inputs["Fac"])
    links.new(ramp.outputs["Color"], emission.inputs["Color"])
    links.new(emission.outputs["Emission"], nodes["Material Output"].inputs["Surface"])
    return m


def _halves(img):
    return [img[25:55, cols].reshape(-1, 3).mean(0) for cols in (slice(8, 30), slice(50, 72))]


@pytest.mark.parametrize("output", ["Fac", "Color"])
def test_intensity_through_a_colour_ramp_matches_cycles(blender, empty_scene, tmp_path, output):
    bpy, scene = blender, empty_scene
    _cloud(bpy, _ramped(bpy, "intensity", output))
    _setup(bpy, scene)
    ours, theirs, report = _both(bpy, scene, tmp_path, f"intensity_{output}")
    for mine, cycles, t, wrong in zip(_halves(ours), _halves(theirs), INTENSITY, CLASSIFICATION):
        np.testing.assert_allclose(mine, _ramp(t), rtol=COLOUR_RTOL, atol=0.01)
        np.testing.assert_allclose(mine, cycles, rtol=COLOUR_RTOL, atol=0.01)
        # Reading the other attribute would fail the tolerance.
        assert not np.allclose(_ramp(wrong), cycles, rtol=COLOUR_RTOL, atol=0.01)
    assert not [line for line in report if "not supported" in line or "attribute" in line], report


def test_a_missing_attribute_reads_zero_as_in_cycles(blender, empty_scene, tmp_path):
    bpy, scene = blender, empty_scene
    _cloud(bpy, _ramped(bpy, "intensity"), with_attributes=False)
    _setup(bpy, scene)
    ours, theirs, _ = _both(bpy, scene, tmp_path, "missing")
    for mine, cycles in zip(_halves(ours), _halves(theirs)):
        np.testing.assert_allclose(mine, _ramp(0.0), rtol=COLOUR_RTOL, atol=0.01)
        np.testing.assert_allclose(mine, cycles, rtol=COLOUR_RTOL, atol=0.01)


def test_object_attributes_are_compiled_not_read_from_the_points(blender, empty_scene):
    """An Attribute node of the object (not the geometry) kind reads the instance's value
    (tests/blender/test_object_info_light_path.py), not a point attribute: nothing said."""
    bpy = blender
    from splat_tracer.blender.export import shading as export_shading
    from splat_tracer.render import shading

    m = _ramped(bpy, "intensity")
    m.node_tree.nodes["Attribute"].attribute_type = "OBJECT"
    report = shading.Report()
    material = export_shading.material_of(m, report)
    assert not [line for line in report.lines if "Attribute" in line], report.lines
    assert material.program.object_attributes == (("OBJECT", "intensity"),)
    assert material.program.attributes == ()


def test_an_attribute_linked_straight_into_the_colour_is_read_not_the_point_colours(blender, empty_scene,
                                                                                      tmp_path):
    """Attribute 'intensity' -> Emission Color directly: the intensity grey, as in Cycles (the
    constant path's "the points' own colours" is for colour attributes only)."""
    bpy, scene = blender, empty_scene
    m = bpy.data.materials.new("Direct")
    nodes, links = m.node_tree.nodes, m.node_tree.links
    nodes.remove(nodes["Principled BSDF"])
    emission, attribute = nodes.new("ShaderNodeEmission"), nodes.new("ShaderNodeAttribute")
    attribute.attribute_name = "intensity"
    links.new(attribute.outputs["Color"], emission.inputs["Color"])
    links.new(emission.outputs["Emission"], nodes["Material Output"].inputs["Surface"])
    _cloud(bpy, m)
    _setup(bpy, scene)
    ours, theirs, _ = _both(bpy, scene, tmp_path, "direct")
    for mine, cycles, t in zip(_halves(ours), _halves(theirs), INTENSITY):
        np.testing.assert_allclose(mine, (t, t, t), rtol=COLOUR_RTOL, atol=0.01)
        np.testing.assert_allclose(mine, cycles, rtol=COLOUR_RTOL, atol=0.01)


@pytest.mark.parametrize("domain", ["POINT", "FACE", "CORNER"])
def test_a_mesh_float_attribute_drives_base_colour_as_in_cycles(blender, empty_scene, tmp_path, domain):
    """A lit floor (2 x 1 faces over -1..1) whose float attribute `intensity`, on its vertices
    (0.5 + 0.3 x: interpolated), faces or face corners (0.2 left, 0.8 right), feeds Base Color
    through a Color Ramp; `classification` (the other way round) is the wrong one."""
    import bmesh

    from test_node_materials import _material
    from test_scene_export import mesh_object

    bpy, scene = blender, empty_scene
    m, nodes, links, shader = _material(bpy, "Floor")
    attribute, ramp = nodes.new("ShaderNodeAttribute"), nodes.new("ShaderNodeValToRGB")
    attribute.attribute_name = "intensity"
    for element, colour in zip(ramp.color_ramp.elements, RAMP):
        element.color = (*colour, 1.0)
    links.new(attribute.outputs["Fac"], ramp.inputs["Fac"])
    links.new(ramp.outputs["Color"], shader.inputs["Base Color"])
    obj = mesh_object(bpy, "Floor", lambda bm: bmesh.ops.create_grid(bm, x_segments=2, y_segments=1, size=1.0),
                      materials=[m])
    mesh = obj.data
    if domain == "POINT":
        x = np.array([v.co.x for v in mesh.vertices])
        values, other = 0.5 + 0.3 * x, 0.5 - 0.3 * x
    else:
        x = np.array([p.center.x for p in mesh.polygons])
        if domain == "CORNER":
            x = np.repeat(x, [p.loop_total for p in mesh.polygons])  # a fresh mesh's loops run face by face
        values, other = np.where(x < 0, *INTENSITY), np.where(x < 0, *CLASSIFICATION)
    mesh.attributes.new("intensity", "FLOAT", domain).data.foreach_set("value", values.astype(np.float32))
    mesh.attributes.new("classification", "FLOAT", domain).data.foreach_set("value", other.astype(np.float32))
    _setup(bpy, scene)
    ours, theirs, report = _both(bpy, scene, tmp_path, f"mesh_{domain}")
    means = (0.35, 0.65) if domain == "POINT" else INTENSITY
    wrongs = (0.65, 0.35) if domain == "POINT" else CLASSIFICATION
    for mine, cycles, t, wrong in zip(_halves(ours), _halves(theirs), means, wrongs):
        np.testing.assert_allclose(mine, cycles, rtol=COLOUR_RTOL, atol=0.01)
        # Lit by the same sun, the other attribute's albedo would fail the tolerance.
        assert not np.allclose(cycles * _ramp(wrong) / _ramp(t), cycles, rtol=COLOUR_RTOL, atol=0.01)
    assert not [line for line in report if "attribute" in line], report


def test_more_attributes_than_carried_are_said_and_read_zero(blender, empty_scene, tmp_path):
    """Five names (the core carries four, three floats each): the last by name reads 0, said
    once; the others still read their values."""
    from test_scene_export import render, stats

    bpy, scene = blender, empty_scene
    m = _ramped(bpy, "intensity")
    nodes, links = m.node_tree.nodes, m.node_tree.links
    total = nodes["Color Ramp"].inputs["Fac"]
    for name in ("a1", "a2", "a3", "zz"):  # summed into the ramp's input with the intensity
        extra, add = nodes.new("ShaderNodeAttribute"), nodes.new("ShaderNodeMath")
        extra.attribute_name = name
        links.new(_live_source(total), add.inputs[0])
        links.new(extra.outputs["Fac"], add.inputs[1])
        links.new(add.outputs[0], total)
    _cloud(bpy, m, extra={"zz": 0.5})  # read, it would move the ramp by half its length
    _setup(bpy, scene)
    ours = render(bpy, scene, tmp_path / "many.exr", (80, 80))["ViewLayer"]["Combined"][..., :3]
    said = [line for line in stats()["report"] if "point attributes" in line]
    assert said == ["the materials read more point attributes than the renderer carries (4 of them, by name); "
                    "attribute 'zz' reads 0"], said
    for mine, t in zip(_halves(ours), INTENSITY):  # a1..a3 are missing (0): the intensity alone
        np.testing.assert_allclose(mine, _ramp(t), rtol=COLOUR_RTOL, atol=0.01)


def _live_source(socket):
    return next(link.from_socket for link in socket.links)
