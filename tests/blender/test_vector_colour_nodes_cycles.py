"""Vector Rotate, Map Range (vector), Vector and Float Curves, Separate/Combine Color (HSL),
Wavelength, Vector Transform, the Normal node and the Gabor Texture (issue 24) through
Blender, side by side with Cycles on test_node_materials' floor (80x80 px, orthographic, sun
30 degrees off the vertical, 16 samples).

Tolerances: correlation >= TEXTURE_CORRELATION (0.95, the issue's bar) of the luminance per
pixel and the mean colour within COLOUR_RTOL (5 %); measured values are printed. Each test
also renders a wrong variant (the rotation's sense flipped, the curve held instead of
extrapolated, the wrong space) and shows it fails.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from test_node_materials import (COLOUR_RTOL, SIZE, TEXTURE_CORRELATION, _both, _floor_both, _material, _setup,
                                 correlation, plane, render)


def _rotated_checker(bpy):
    """UV -> Vector Rotate (Z axis about the floor's middle, inverted) -> Map Range (vector,
    0..1 to -1..1) -> Vector Curves (X bent, extrapolated past its points) -> Checker ->
    Separate Color (HSL), hue through a Float Curve -> Combine Color (HSL) -> Base Color."""
    m, nodes, links, shader = _material(bpy, "Rotated")
    coords, rotate, remap, vcurves, checker, sep, fcurve, comb = (nodes.new(t) for t in (
        "ShaderNodeTexCoord", "ShaderNodeVectorRotate", "ShaderNodeMapRange", "ShaderNodeVectorCurve",
        "ShaderNodeTexChecker", "ShaderNodeSeparateColor", "ShaderNodeFloatCurve", "ShaderNodeCombineColor"))
    rotate.rotation_type, rotate.invert = "Z_AXIS", True
    rotate.inputs["Center"].default_value = (0.5, 0.5, 0.0)
    rotate.inputs["Angle"].default_value = 0.6
    remap.data_type = "FLOAT_VECTOR"
    vectors = {s.name: s for s in remap.inputs if s.type == "VECTOR"}
    vectors["To Min"].default_value = (-1.0, -1.0, -1.0)
    x_curve = vcurves.mapping.curves[0]  # X: points at (-1, -1) and (1, 1); bent and cut short
    x_curve.points[1].location = (0.5, 0.2)
    x_curve.points.new(-0.2, -0.6)
    vcurves.mapping.extend = "EXTRAPOLATED"
    vcurves.mapping.update()
    checker.inputs["Scale"].default_value = 2.0
    checker.inputs["Color1"].default_value = (0.9, 0.6, 0.2, 1)
    checker.inputs["Color2"].default_value = (0.1, 0.3, 0.7, 1)
    sep.mode = comb.mode = "HSL"
    fcurve.mapping.curves[0].points.new(0.4, 0.8)
    fcurve.mapping.update()
    links.new(coords.outputs["UV"], rotate.inputs["Vector"])
    links.new(rotate.outputs["Vector"], next(s for s in remap.inputs if s.name == "Vector"))
    links.new(next(s for s in remap.outputs if s.name == "Vector"), vcurves.inputs["Vector"])
    links.new(vcurves.outputs["Vector"], checker.inputs["Vector"])
    links.new(checker.outputs["Color"], sep.inputs["Color"])
    links.new(sep.outputs[0], fcurve.inputs["Value"])
    links.new(fcurve.outputs["Value"], comb.inputs[0])
    links.new(sep.outputs[1], comb.inputs[1])
    links.new(sep.outputs[2], comb.inputs[2])
    links.new(comb.outputs["Color"], shader.inputs["Base Color"])
    return m, rotate, vcurves


def _measure(ours, theirs):
    r = correlation(ours, theirs)
    off = np.abs(ours.reshape(-1, 3).mean(0) / theirs.reshape(-1, 3).mean(0) - 1).max()
    return r, off


def test_rotated_curved_hsl_checker_matches_cycles(blender, empty_scene, tmp_path):
    bpy, scene = blender, empty_scene
    m, rotate, vcurves = _rotated_checker(bpy)
    ours, theirs, report = _floor_both(bpy, scene, tmp_path, m, "rotated")
    r, off = _measure(ours, theirs)
    print(f"rotated checker: correlation {r:.4f}, mean colour {off:.4f} off")
    assert r >= TEXTURE_CORRELATION and off <= COLOUR_RTOL
    assert not [line for line in report if "Rotated" in line], report
    rotate.invert = False  # the rotation's sense flipped
    wrong = render(bpy, scene, tmp_path / "wrong.exr", (SIZE, SIZE))["ViewLayer"]["Combined"][..., :3]
    print(f"rotation sense flipped: correlation {correlation(wrong, theirs):.4f}")
    assert correlation(wrong, theirs) < TEXTURE_CORRELATION
    rotate.invert = True
    vcurves.mapping.extend = "HORIZONTAL"  # Cycles would hold too: ours must follow, not extrapolate
    vcurves.mapping.update()
    held = render(bpy, scene, tmp_path / "held.exr", (SIZE, SIZE))["ViewLayer"]["Combined"][..., :3]
    print(f"extension held vs Cycles extrapolated: correlation {correlation(held, theirs):.4f}")
    assert correlation(held, theirs) < TEXTURE_CORRELATION


def _spectrum(bpy, floor_space):
    """An Emission floor: the world position through Vector Transform (world -> object,
    point) on a rotated, scaled, moved floor, its X through Map Range (380-780 nm) into
    Wavelength; times the Normal node's Dot with the Vector Transform of the geometry normal
    (world -> camera, normal) against the camera's view axis reversed, -Z: 1 on this floor."""
    m = bpy.data.materials.new("Spectrum")
    nodes, links = m.node_tree.nodes, m.node_tree.links
    output = next(n for n in nodes if n.type == "OUTPUT_MATERIAL")
    geometry, to_object, sep, nm, wavelength, to_camera, normal, scale, emission = (nodes.new(t) for t in (
        "ShaderNodeNewGeometry", "ShaderNodeVectorTransform", "ShaderNodeSeparateXYZ", "ShaderNodeMapRange",
        "ShaderNodeWavelength", "ShaderNodeVectorTransform", "ShaderNodeNormal", "ShaderNodeVectorMath",
        "ShaderNodeEmission"))
    to_object.vector_type, to_object.convert_from, to_object.convert_to = "POINT", "WORLD", floor_space
    to_camera.vector_type, to_camera.convert_from, to_camera.convert_to = "NORMAL", "WORLD", "CAMERA"
    nm.inputs["From Min"].default_value, nm.inputs["From Max"].default_value = -1.0, 1.0
    nm.inputs["To Min"].default_value, nm.inputs["To Max"].default_value = 380.0, 780.0
    normal.outputs["Normal"].default_value = (0.0, 0.0, -2.0)
    scale.operation = "SCALE"
    links.new(geometry.outputs["Position"], to_object.inputs["Vector"])
    links.new(to_object.outputs["Vector"], sep.inputs["Vector"])
    links.new(sep.outputs["X"], nm.inputs["Value"])
    links.new(nm.outputs["Result"], wavelength.inputs["Wavelength"])
    links.new(geometry.outputs["Normal"], to_camera.inputs["Vector"])
    links.new(to_camera.outputs["Vector"], normal.inputs["Normal"])
    links.new(wavelength.outputs["Color"], scale.inputs[0])
    links.new(normal.outputs["Dot"], scale.inputs["Scale"])
    links.new(scale.outputs["Vector"], emission.inputs["Color"])
    links.new(emission.outputs[0], output.inputs["Surface"])
    return m, to_object


def test_wavelength_over_an_object_space_floor_matches_cycles(blender, empty_scene, tmp_path):
    bpy, scene = blender, empty_scene
    m, to_object = _spectrum(bpy, "OBJECT")
    floor = plane(bpy, "Floor", 2.0, (0.1, -0.05, 0), m)
    floor.rotation_euler = (0, 0, math.radians(25))
    floor.scale = (1.6, 1.3, 1.0)
    _setup(bpy, scene)
    ours, theirs, report = _both(bpy, scene, tmp_path, "spectrum")
    r, off = _measure(ours, theirs)
    print(f"spectrum: correlation {r:.4f}, mean colour {off:.4f} off, max |diff| {np.abs(ours - theirs).max():.4f}")
    assert r >= TEXTURE_CORRELATION and off <= COLOUR_RTOL
    assert not [line for line in report if "Spectrum" in line], report
    to_object.convert_to = "CAMERA"  # the wrong space: the spectrum runs across the view, unrotated
    wrong = render(bpy, scene, tmp_path / "wrong.exr", (SIZE, SIZE))["ViewLayer"]["Combined"][..., :3]
    print(f"camera space instead: correlation {correlation(wrong, theirs):.4f}")
    assert correlation(wrong, theirs) < TEXTURE_CORRELATION


def test_rgb_curves_beyond_their_points_extrapolate_as_in_cycles(blender, empty_scene, tmp_path):
    """A gradient stretched to -0.5..1.5 (Map Range) through RGB Curves whose red curve is
    bent and the combined curve cut short (points over 0..0.8): Cycles extrapolates beyond the
    points' range along the curves' end slopes (the mapping's Extrapolated extension, the
    default); holding the ends, as this engine did before, fails."""
    bpy, scene = blender, empty_scene
    m, nodes, links, shader = _material(bpy, "Curves")
    coords, gradient, stretch, curves = (nodes.new(t) for t in ("ShaderNodeTexCoord", "ShaderNodeTexGradient",
                                                                "ShaderNodeMapRange", "ShaderNodeRGBCurve"))
    stretch.inputs["To Min"].default_value, stretch.inputs["To Max"].default_value = -0.5, 1.5
    curves.mapping.curves[3].points[1].location = (0.8, 0.9)
    curves.mapping.curves[0].points.new(0.5, 0.2)
    curves.mapping.update()
    assert curves.mapping.extend == "EXTRAPOLATED"  # Blender's default
    links.new(coords.outputs["UV"], gradient.inputs["Vector"])
    links.new(gradient.outputs["Fac"], stretch.inputs["Value"])
    links.new(stretch.outputs["Result"], curves.inputs["Color"])
    links.new(curves.outputs["Color"], shader.inputs["Base Color"])
    ours, theirs, report = _floor_both(bpy, scene, tmp_path, m, "curves_beyond")
    r, off = _measure(ours, theirs)
    print(f"RGB curves beyond the points: correlation {r:.4f}, mean colour {off:.4f} off")
    assert r >= TEXTURE_CORRELATION and off <= COLOUR_RTOL
    curves.mapping.extend = "HORIZONTAL"  # our render held at the ends, Cycles' still extrapolated
    curves.mapping.update()
    held = render(bpy, scene, tmp_path / "held.exr", (SIZE, SIZE))["ViewLayer"]["Combined"][..., :3]
    r_held, off_held = _measure(held, theirs)
    print(f"held at the ends: correlation {r_held:.4f}, mean colour {off_held:.4f} off")
    assert off_held > COLOUR_RTOL or r_held < TEXTURE_CORRELATION


def _gabor_floor(bpy, kind):
    m, nodes, links, shader = _material(bpy, "Gabor")
    coords, gabor, ramp = (nodes.new(t) for t in ("ShaderNodeTexCoord", "ShaderNodeTexGabor", "ShaderNodeValToRGB"))
    gabor.gabor_type = kind
    gabor.inputs["Scale"].default_value = 4.0
    gabor.inputs["Frequency"].default_value = 2.5
    gabor.inputs["Anisotropy"].default_value = 0.7
    angle, direction = (next(s for s in gabor.inputs if s.name == "Orientation" and s.type == t)
                        for t in ("VALUE", "VECTOR"))
    angle.default_value, direction.default_value = 0.5, (0.3, 0.8, 0.5)
    ramp.color_ramp.elements[0].color = (0.05, 0.1, 0.4, 1)
    ramp.color_ramp.elements[1].color = (1.0, 0.8, 0.3, 1)
    links.new(coords.outputs["Object"], gabor.inputs["Vector"])
    links.new(gabor.outputs["Value"], ramp.inputs["Fac"])
    links.new(ramp.outputs["Color"], shader.inputs["Base Color"])
    return m, gabor



@pytest.mark.parametrize("kind", ["2D", "3D"])
def test_gabor_texture_matches_cycles(blender, empty_scene, tmp_path, kind):
    """Gabor Texture (anisotropy 0.7, frequency 2.5) through a Color Ramp on object
    coordinates; its Phase output instead fails."""
    bpy, scene = blender, empty_scene
    m, gabor = _gabor_floor(bpy, kind)
    ours, theirs, report = _floor_both(bpy, scene, tmp_path, m, f"gabor_{kind}")
    r, off = _measure(ours, theirs)
    print(f"gabor {kind}: correlation {r:.4f}, mean colour {off:.4f} off")
    assert r >= TEXTURE_CORRELATION and off <= COLOUR_RTOL
    assert not [line for line in report if "Gabor" in line], report
    links = m.node_tree.links
    links.new(gabor.outputs["Phase"], m.node_tree.nodes["Color Ramp"].inputs["Fac"])
    wrong = render(bpy, scene, tmp_path / "wrong.exr", (SIZE, SIZE))["ViewLayer"]["Combined"][..., :3]
    print(f"gabor {kind} phase instead: correlation {correlation(wrong, theirs):.4f}")
    assert correlation(wrong, theirs) < TEXTURE_CORRELATION


TRANSFORMS = [("WORLD", "OBJECT"), ("OBJECT", "WORLD"), ("WORLD", "CAMERA"), ("CAMERA", "OBJECT"),
              ("OBJECT", "CAMERA")]
TRANSFORM_ATOL = 0.01  # mean absolute difference per channel (Cycles' 16 samples filter the edges)


def test_vector_transform_spaces_match_cycles(blender, empty_scene, tmp_path):
    """Every kind (point, vector, normal) between world, object and camera space, of the
    world position, on a turned, unevenly scaled, moved floor under a turned camera: Emission of the result's
    absolute value x 0.5, beside Cycles; mean absolute difference per channel within
    TRANSFORM_ATOL, and each differs from the untransformed position by more."""
    bpy, scene = blender, empty_scene
    m = bpy.data.materials.new("Spaces")
    nodes, links = m.node_tree.nodes, m.node_tree.links
    output = next(n for n in nodes if n.type == "OUTPUT_MATERIAL")
    geometry, transform, absolute, emission = (nodes.new(t) for t in (
        "ShaderNodeNewGeometry", "ShaderNodeVectorTransform", "ShaderNodeVectorMath", "ShaderNodeEmission"))
    absolute.operation = "ABSOLUTE"
    emission.inputs["Strength"].default_value = 0.5
    links.new(geometry.outputs["Position"], transform.inputs["Vector"])
    links.new(transform.outputs["Vector"], absolute.inputs[0])
    links.new(absolute.outputs["Vector"], emission.inputs["Color"])
    links.new(emission.outputs[0], output.inputs["Surface"])
    floor = plane(bpy, "Floor", 2.0, (0.2, -0.1, 0.3), m)
    floor.rotation_euler = (0.3, -0.2, math.radians(35))
    floor.scale = (1.7, 1.2, 0.6)
    _setup(bpy, scene)
    scene.camera.rotation_euler = (0.1, -0.05, 0.7)  # turned about its view, so camera space is no mere flip
    size = (48, 48)
    worst = 0.0
    for kind in ("POINT", "VECTOR", "NORMAL"):
        for src, dst in TRANSFORMS:
            transform.vector_type, transform.convert_from, transform.convert_to = kind, src, dst
            ours = render(bpy, scene, tmp_path / "ours.exr", size)["ViewLayer"]["Combined"][..., :3]
            scene.render.engine = "CYCLES"
            try:
                theirs = render(bpy, scene, tmp_path / "cycles.exr", size)["ViewLayer"]["Combined"][..., :3]
            finally:
                scene.render.engine = "SPLAT_TRACER"
            diff = np.abs(ours - theirs).reshape(-1, 3).mean(0).max()
            worst = max(worst, diff)
            print(f"vector transform {kind} {src}->{dst}: mean |difference| {diff:.4f}")
            assert diff <= TRANSFORM_ATOL, (kind, src, dst)
            untouched = links.new(geometry.outputs["Position"], absolute.inputs[0])
            plain = render(bpy, scene, tmp_path / "plain.exr", size)["ViewLayer"]["Combined"][..., :3]
            links.remove(untouched)
            links.new(transform.outputs["Vector"], absolute.inputs[0])
            assert np.abs(plain - theirs).reshape(-1, 3).mean(0).max() > 3 * TRANSFORM_ATOL, (kind, src, dst)
    print(f"vector transform: worst mean |difference| {worst:.4f}")
