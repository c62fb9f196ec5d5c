"""Mix and Add Shaders with linked inputs compiled into node programs (export/shader_mix.py):
per shading point, the program gives what the constant blend (shading._combine) gives for the
same values, and a mix that nothing links keeps the constant path."""
from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture
def es(blender):
    from splat_tracer.blender.export import shading as export_shading
    return export_shading


@pytest.fixture
def report():
    from splat_tracer.render import shading
    return shading.Report()


FIELDS = ("base_colour", "metallic", "roughness", "ior", "transmission", "alpha", "emission", "specular_level",
          "metal_colour")


def fields_at(material, n=1, **globals_):
    """Each Material field at n shading points: the program's output where it drives it,
    else the constant ((n, width) arrays)."""
    from splat_tracer.render import nodes
    regs = nodes.run(material.program, n, **globals_) if material.program is not None else None
    out = {}
    for name in FIELDS:
        width = nodes.OUTPUTS[name]
        if regs is not None and material.program.drives(name):
            reg = material.program.outputs[list(nodes.OUTPUTS).index(name)]
            out[name] = regs[:, reg:reg + width].astype(np.float64)
        elif name == "metal_colour" and material.metal_colour is None:  # the base colour's, as the core reads it
            out[name] = out["base_colour"]
        else:
            out[name] = np.broadcast_to(np.asarray(getattr(material, name), np.float64).reshape(1, width), (n, width))
    return out


def _tree(bpy, name):
    material = bpy.data.materials.new(name)
    nodes, links = material.node_tree.nodes, material.node_tree.links
    nodes.clear()
    output = nodes.new("ShaderNodeOutputMaterial")
    return material, nodes, links, output


def _value(nodes, links, socket, value):
    """Links a Value node holding `value` into `socket` (a link the program must follow)."""
    node = nodes.new("ShaderNodeValue")
    node.outputs[0].default_value = value
    links.new(node.outputs[0], socket)
    return node


def _rgb(nodes, links, socket, colour):
    node = nodes.new("ShaderNodeRGB")
    node.outputs[0].default_value = (*colour, 1.0)
    links.new(node.outputs[0], socket)
    return node


def diffuse_glossy(bpy, name, fac, link_fac, link_colour=False, transparent=False):
    """Mix(fac) of a red Diffuse and a blue Glossy (roughness 0.2) -- or a Transparent BSDF."""
    material, nodes, links, output = _tree(bpy, name)
    diffuse = nodes.new("ShaderNodeBsdfDiffuse")
    second = nodes.new("ShaderNodeBsdfTransparent" if transparent else "ShaderNodeBsdfGlossy")
    if link_colour:
        _rgb(nodes, links, diffuse.inputs["Color"], (1.0, 0.0, 0.0))
    else:
        diffuse.inputs["Color"].default_value = (1.0, 0.0, 0.0, 1.0)
    if not transparent:
        second.inputs["Color"].default_value = (0.0, 0.0, 1.0, 1.0)
        second.inputs["Roughness"].default_value = 0.2
    mix = nodes.new("ShaderNodeMixShader")
    if link_fac:
        _value(nodes, links, mix.inputs[0], fac)
    else:
        mix.inputs[0].default_value = fac
    links.new(diffuse.outputs[0], mix.inputs[1])
    links.new(second.outputs[0], mix.inputs[2])
    links.new(mix.outputs[0], output.inputs["Surface"])
    return material


def assert_same_fields(got, want):
    for name in FIELDS:
        np.testing.assert_allclose(got[name], np.broadcast_to(want[name][:1], got[name].shape), rtol=1e-5,
                                   atol=1e-6, err_msg=name)


@pytest.mark.parametrize("fac", [0.0, 0.25, 0.6, 1.0, 1.7])
@pytest.mark.parametrize("transparent", [False, True])
def test_a_linked_fac_blends_as_the_constant_path(blender, empty_scene, es, report, fac, transparent):
    """A Fac from a Value node: the program gives the fields the constant blend gives for a
    Fac of that value (1.7: saturated, as Cycles does)."""
    linked = es.material_of(diffuse_glossy(blender, "Linked", fac, True, transparent=transparent), report)
    constant = es.material_of(diffuse_glossy(blender, "Constant", fac, False, transparent=transparent), report)
    assert constant.program is None and linked.program is not None
    assert linked.program.drives("base_colour") and linked.program.drives("alpha") == transparent
    assert_same_fields(fields_at(linked), fields_at(constant))
    # The approximation is said; the linked Fac is compiled, not replaced by its default.
    assert "material 'Linked': Mix and Add Shaders are approximated by blending their shaders' parameters" \
        in report.lines
    assert not [line for line in report.lines if "Fac" in line or "driven by" in line], report.lines


def test_a_wrong_fac_would_differ(blender, empty_scene, es, report):
    """The comparison above can fail: the Fac's default (0.5) in place of the linked 0.25."""
    linked = es.material_of(diffuse_glossy(blender, "Linked", 0.25, True), report)
    constant = es.material_of(diffuse_glossy(blender, "Constant", 0.5, False), report)
    with pytest.raises(AssertionError):
        assert_same_fields(fields_at(linked), fields_at(constant))


def test_the_fac_varies_per_shading_point(blender, empty_scene, es, report):
    """Fac = the generated x coordinate: at each point the fields the constant blend gives
    for that Fac (clamped to 0..1, as Cycles does)."""
    material, nodes, links, output = _tree(blender, "Ramp")
    diffuse, glossy = nodes.new("ShaderNodeBsdfDiffuse"), nodes.new("ShaderNodeBsdfGlossy")
    diffuse.inputs["Color"].default_value = (1.0, 0.0, 0.0, 1.0)
    glossy.inputs["Color"].default_value = (0.0, 0.0, 1.0, 1.0)
    glossy.inputs["Roughness"].default_value = 0.2
    coords, separate = nodes.new("ShaderNodeTexCoord"), nodes.new("ShaderNodeSeparateXYZ")
    mix = nodes.new("ShaderNodeMixShader")
    links.new(coords.outputs["Generated"], separate.inputs[0])
    links.new(separate.outputs["X"], mix.inputs[0])
    links.new(diffuse.outputs[0], mix.inputs[1])
    links.new(glossy.outputs[0], mix.inputs[2])
    links.new(mix.outputs[0], output.inputs["Surface"])
    m = es.material_of(material, report)
    x = np.array([-0.5, 0.0, 0.3, 0.75, 1.0, 2.0])
    got = fields_at(m, len(x), generated=np.stack([x, 0 * x, 0 * x], 1))
    for i, f in enumerate(np.clip(x, 0, 1)):
        constant = es.material_of(diffuse_glossy(blender, f"Constant{i}", float(f), False), report)
        assert_same_fields({k: v[i:i + 1] for k, v in got.items()}, fields_at(constant))
    assert not m.program.drives("alpha") and not m.program.drives("emission")  # constant: the constant path


def test_a_textured_branch_is_compiled(blender, empty_scene, es, report):
    """A branch's linked Base Color (an RGB node) under a constant Fac: the blend of its value."""
    linked = es.material_of(diffuse_glossy(blender, "Linked", 0.3, False, link_colour=True), report)
    constant = es.material_of(diffuse_glossy(blender, "Constant", 0.3, False), report)
    assert linked.program.drives("base_colour")
    assert not linked.program.drives("roughness")  # nothing linked reaches it: the constant path
    assert_same_fields(fields_at(linked), fields_at(constant))
    assert not [line for line in report.lines if "driven by" in line], report.lines


def add_textured(bpy, name, link):
    """Add Shader of a Principled (Base Color, Roughness) and an Emission (Color, Strength),
    their inputs from RGB/Value nodes when `link`."""
    material, nodes, links, output = _tree(bpy, name)
    principled, emission = nodes.new("ShaderNodeBsdfPrincipled"), nodes.new("ShaderNodeEmission")
    add = nodes.new("ShaderNodeAddShader")
    values = [(principled.inputs["Base Color"], (0.2, 0.5, 0.1)), (principled.inputs["Roughness"], 0.35),
              (emission.inputs["Color"], (0.9, 0.4, 0.0)), (emission.inputs["Strength"], 2.5)]
    for socket, value in values:
        if not link:
            socket.default_value = (*value, 1.0) if isinstance(value, tuple) else value
        elif isinstance(value, tuple):
            _rgb(nodes, links, socket, value)
        else:
            _value(nodes, links, socket, value)
    links.new(principled.outputs[0], add.inputs[0])
    links.new(emission.outputs[0], add.inputs[1])
    links.new(add.outputs[0], output.inputs["Surface"])
    return material


def test_add_shader_of_textured_branches(blender, empty_scene, es, report):
    linked = es.material_of(add_textured(blender, "Linked", True), report)
    constant = es.material_of(add_textured(blender, "Constant", False), report)
    assert constant.program is None
    assert all(linked.program.drives(n) for n in ("base_colour", "roughness", "emission"))
    assert_same_fields(fields_at(linked), fields_at(constant))
    np.testing.assert_allclose(fields_at(linked)["emission"][0], (2.25, 1.0, 0.0), rtol=1e-6)


def nested(bpy, name, link):
    """Mix(0.4) of [Mix(0.7) of a Principled and an Emission] and a Transparent BSDF; the
    inner Fac and the Principled's Metallic linked when `link`."""
    material, nodes, links, output = _tree(bpy, name)
    principled, emission = nodes.new("ShaderNodeBsdfPrincipled"), nodes.new("ShaderNodeEmission")
    transparent = nodes.new("ShaderNodeBsdfTransparent")
    inner, outer = nodes.new("ShaderNodeMixShader"), nodes.new("ShaderNodeMixShader")
    principled.inputs["Base Color"].default_value = (0.1, 0.6, 0.9, 1.0)
    emission.inputs["Strength"].default_value = 4.0
    outer.inputs[0].default_value = 0.4
    if link:
        _value(nodes, links, inner.inputs[0], 0.7)
        _value(nodes, links, principled.inputs["Metallic"], 0.8)
    else:
        inner.inputs[0].default_value, principled.inputs["Metallic"].default_value = 0.7, 0.8
    links.new(principled.outputs[0], inner.inputs[1])
    links.new(emission.outputs[0], inner.inputs[2])
    links.new(inner.outputs[0], outer.inputs[1])
    links.new(transparent.outputs[0], outer.inputs[2])
    links.new(outer.outputs[0], output.inputs["Surface"])
    return material


def test_nested_mixes(blender, empty_scene, es, report):
    linked = es.material_of(nested(blender, "Linked", True), report)
    constant = es.material_of(nested(blender, "Constant", False), report)
    assert constant.program is None and linked.program is not None
    assert_same_fields(fields_at(linked), fields_at(constant))
    assert constant.alpha == pytest.approx(0.6) and constant.emission == pytest.approx((0.6 * 0.7 * 4,) * 3)


def test_point_colours_under_a_mix_with_a_linked_fac(blender, empty_scene, es, report):
    """A Color Attribute straight into one branch's colour: with a linked Fac the program reads
    the points' colours for that branch (the constant path would take them for the whole blend)."""
    material, nodes, links, output = _tree(blender, "Scan")
    diffuse, glossy = nodes.new("ShaderNodeBsdfDiffuse"), nodes.new("ShaderNodeBsdfGlossy")
    attribute = nodes.new("ShaderNodeVertexColor")
    glossy.inputs["Color"].default_value = (0.0, 0.0, 1.0, 1.0)
    mix = nodes.new("ShaderNodeMixShader")
    links.new(attribute.outputs["Color"], diffuse.inputs["Color"])
    _value(nodes, links, mix.inputs[0], 0.25)
    links.new(diffuse.outputs[0], mix.inputs[1])
    links.new(glossy.outputs[0], mix.inputs[2])
    links.new(mix.outputs[0], output.inputs["Surface"])
    m = es.material_of(material, report)
    got = fields_at(m, 1, point_colour=(0.2, 0.4, 0.8))
    # The two lobes kept apart: the diffuse share the points' colours, the metallic one the Glossy's.
    np.testing.assert_allclose(got["base_colour"][0], (0.2, 0.4, 0.8), rtol=1e-6)
    np.testing.assert_allclose(got["metal_colour"][0], (0.0, 0.0, 1.0), atol=1e-6)
    np.testing.assert_allclose(got["metallic"][0], 0.25, rtol=1e-6)
    # Without the Fac's link nothing needs a program: the constant path, as before.
    links.remove(mix.inputs[0].links[0])
    assert es.material_of(material, report).program is None


def test_a_linked_normal_under_a_mix_is_blended(blender, empty_scene, es, report):
    material, nodes, links, output = _tree(blender, "Bumpy")
    diffuse, glossy = nodes.new("ShaderNodeBsdfDiffuse"), nodes.new("ShaderNodeBsdfGlossy")
    mix = nodes.new("ShaderNodeMixShader")
    mix.inputs[0].default_value = 0.5
    tilted = nodes.new("ShaderNodeCombineXYZ")
    tilted.inputs[0].default_value, tilted.inputs[2].default_value = 1.0, 1.0
    links.new(tilted.outputs[0], glossy.inputs["Normal"])
    links.new(diffuse.outputs[0], mix.inputs[1])
    links.new(glossy.outputs[0], mix.inputs[2])
    links.new(mix.outputs[0], output.inputs["Surface"])
    m = es.material_of(material, report)
    assert m.program.drives("normal") and not m.program.drives("base_colour")
    from splat_tracer.render import nodes as programs
    regs = programs.run(m.program, 1, N=(0.0, 0.0, 1.0))[0]
    reg = m.program.outputs[list(programs.OUTPUTS).index("normal")]
    np.testing.assert_allclose(regs[reg:reg + 3], (0.5, 0.0, 1.0), atol=1e-6)  # 0.5 N + 0.5 (1, 0, 1)
