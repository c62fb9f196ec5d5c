"""A Diffuse mixed with a Glossy (the classic Cycles material), side by side with Cycles: the
Mix keeps the two closures' lobes apart (the diffuse of its colour, a GGX metallic lobe of
the Glossy's colour and roughness), rather than one lobe of blended colour and roughness.

The Mix Shader of a red Diffuse BSDF and a grey Glossy BSDF (roughness 0.3), its Fac from a
UV Checker's Fac (0 or 1), a UV Checker's grey levels (0.2 and 0.8), a Fresnel (IOR 1.45:
the classic) or a Layer Weight's Fresnel (Blend 0.3), on a 6 m floor seen at 40 degrees (a sun from the side, a black world, no
bounces) and on a sphere alone seen at an angle (a sun, a bright world, a diffuse and a
glossy bounce; its pixels inside the silhouette compared); 80x80 px, 64 samples.

Tolerances (measured with bpy 5.0.1, printed by each test: correlation >= 0.9999 and means
within 0.7 % everywhere; the one blended lobe of before: 0.74 to 0.99, means up to 160 % off;
a diffuse Principled BSDF, whose own specular layer stays one lobe with the Glossy: 0.9898):
- LOBES_CORRELATION = 0.98: Pearson correlation of the pixels' channel means with Cycles'.
- LOBES_COLOUR_RTOL = 0.05: relative difference of the mean colour, per channel.
Each test renders the old single-lobe blend too and asserts that it fails them, but for a
Fac of 0 or 1, where one closure is left in each cell and the single lobe was exact.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from blender_helpers import add_camera, extension_module
from test_mix_shader_cycles import RED, _checker_fac, _mix_material
from test_node_materials import SIZE, _setup, correlation, plane
from test_scene_export import lamp, pixel_of, render, stats, uv_sphere

LOBES_CORRELATION = 0.98
LOBES_COLOUR_RTOL = 0.05
GREY = (0.8, 0.8, 0.8)


def _diffuse_bsdf(nodes, links):
    shader = nodes.new("ShaderNodeBsdfDiffuse")
    shader.inputs["Color"].default_value = (*RED, 1.0)
    return shader


def _glossy(nodes, links):
    shader = nodes.new("ShaderNodeBsdfGlossy")
    shader.inputs["Color"].default_value = (*GREY, 1.0)
    shader.inputs["Roughness"].default_value = 0.3
    return shader


def _fresnel_fac(nodes, links):
    fresnel = nodes.new("ShaderNodeFresnel")
    fresnel.inputs["IOR"].default_value = 1.45
    return fresnel.outputs["Fac"]


def _soft_checker_fac(nodes, links):
    """A UV Checker's Color into the Fac: Fac 0.2 and 0.8 cells (its grey levels), so that
    both closures are in every cell (a Fac of 0 or 1 leaves one closure, which one blended
    lobe renders exactly)."""
    coords, checker = nodes.new("ShaderNodeTexCoord"), nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 4.0
    checker.inputs["Color1"].default_value = (0.8, 0.8, 0.8, 1)
    checker.inputs["Color2"].default_value = (0.2, 0.2, 0.2, 1)
    links.new(coords.outputs["UV"], checker.inputs["Vector"])
    return checker.outputs["Color"]


def _layer_weight_fac(nodes, links):
    layer_weight = nodes.new("ShaderNodeLayerWeight")
    layer_weight.inputs["Blend"].default_value = 0.3
    return layer_weight.outputs["Fresnel"]


FACS = {"checker": _checker_fac, "soft checker": _soft_checker_fac, "fresnel": _fresnel_fac,
        "layer weight": _layer_weight_fac}


def _floor_scene(bpy, scene, material):
    """A 6 m floor of `material` seen at 40 degrees from above (the Fresnel varies across it),
    a sun, a black world, no bounces: the sun's highlight and the diffuse, 64 samples."""
    plane(bpy, "Floor", 6.0, (0, 0, 0), material)
    _setup(bpy, scene)
    scene.objects["Camera"].location, scene.objects["Camera"].rotation_euler = (0, -2.5, 2.1), (math.radians(50), 0, 0)
    scene.objects["Camera"].data.type = "PERSP"
    # From the side, so that the sun's highlight is at the image's edge and does not swamp it.
    scene.objects["Sun"].rotation_euler = (math.radians(50), 0, math.radians(100))
    scene.cycles.samples = 64


def _sphere_scene(bpy, scene, material):
    """A sphere of `material` alone (no floor: the engine lights a diffuse surface by the
    world through a diffuse bounce, so a floor's light bounced onto the sphere would need one
    more bounce than in Cycles), seen at an angle, a sun and a bright world; a diffuse and a
    glossy bounce (the world in the reflection), 64 samples."""
    uv_sphere(bpy, "Ball", 0.8, (0, 0, 0.8), material)
    add_camera(bpy, scene, (0, -4.2, 2.4), (math.radians(65), 0, 0))
    lamp(bpy, "SUN", rotation=(math.radians(35), 0, math.radians(30)), energy=3.0)
    scene.world = bpy.data.worlds.new("Sky")
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.6, 0.7, 0.9, 1)
    c = scene.cycles
    c.max_bounces, c.diffuse_bounces, c.glossy_bounces, c.transmission_bounces = 2, 1, 1, 0
    c.transparent_max_bounces = 0
    c.samples, c.device, c.use_denoising, c.use_adaptive_sampling = 64, "CPU", False, False


def _ball_pixels(bpy, scene, image):
    """The pixels well inside the sphere's silhouette (0.85 of its radius in the image): the
    material's own, without the background that fills most of the view."""
    centre = np.array(pixel_of(bpy, scene, (0, 0, 0.8)))
    radius = np.hypot(*(np.array(pixel_of(bpy, scene, (0.8, 0, 0.8))) - centre))
    rows, cols = np.mgrid[:image.shape[0], :image.shape[1]]
    inside = np.hypot(rows - centre[0], cols - centre[1]) < 0.85 * radius
    return image[inside][:, None, :]  # (n, 1, 3): an image of the pixels inside


def _render(bpy, scene, tmp_path, name):
    return render(bpy, scene, tmp_path / f"{name}.exr", (SIZE, SIZE))["ViewLayer"]["Combined"][..., :3]


def _single_lobe(monkeypatch):
    """The old blend: one lobe of blended colour, metallic and roughness (the split left out
    of both the constant and the per-shading-point blend)."""
    monkeypatch.setattr(extension_module("blender.export.shading"), "_split_lobes", lambda *a: {})
    monkeypatch.setattr(extension_module("blender.export.shader_mix")._Blender, "_split_lobes", lambda *a: None)


def rgb_correlation(a, b) -> float:
    return float(np.corrcoef(a.ravel(), b.ravel())[0, 1])


def _means(image):
    return image.reshape(-1, 3).mean(0)


def _close(ours, theirs) -> bool:
    return (correlation(ours, theirs) >= LOBES_CORRELATION and
            np.allclose(_means(ours), _means(theirs), rtol=LOBES_COLOUR_RTOL, atol=0.0))


@pytest.mark.parametrize("where", ["floor", "sphere"])
@pytest.mark.parametrize("fac", ["checker", "soft checker", "fresnel", "layer weight"])
def test_a_diffuse_mixed_with_a_glossy_matches_cycles(blender, empty_scene, tmp_path, monkeypatch, fac, where):
    _compare(blender, empty_scene, tmp_path, monkeypatch, fac, where, _diffuse_bsdf)


def _principled(nodes, links):
    """A red Principled BSDF at its defaults: its own specular layer (roughness 0.5)."""
    shader = nodes.new("ShaderNodeBsdfPrincipled")
    shader.inputs["Base Color"].default_value = (*RED, 1.0)
    return shader


def test_a_principled_mixed_with_a_glossy_is_close_to_cycles(blender, empty_scene, tmp_path, monkeypatch):
    """A Principled BSDF's own specular layer and the Glossy become one glossy lobe (its
    roughness weighed by their specular strengths, mostly the Glossy's): measured 0.9898 on
    the sphere, means within 1.1 % (one blended lobe: 0.9251, 3.7 %)."""
    _compare(blender, empty_scene, tmp_path, monkeypatch, "fresnel", "sphere", _principled)


def _compare(blender, empty_scene, tmp_path, monkeypatch, fac, where, diffuse):
    bpy, scene = blender, empty_scene
    material, _ = _mix_material(bpy, "Classic", diffuse, _glossy, FACS[fac])
    if where == "floor":
        _floor_scene(bpy, scene, material)
    else:
        _sphere_scene(bpy, scene, material)
    # On the sphere scene its pixels only (the world and the floor fill most of the view).
    region = (lambda image: image) if where == "floor" else (lambda image: _ball_pixels(bpy, scene, image))
    ours = region(_render(bpy, scene, tmp_path, "ours"))
    report = list(stats()["report"])
    scene.render.engine = "CYCLES"
    try:
        theirs = region(_render(bpy, scene, tmp_path, "cycles"))
    finally:
        scene.render.engine = "SPLAT_TRACER"
    r = correlation(ours, theirs)
    print(f"{fac} on the {where}: correlation {r:.4f} (RGB {rgb_correlation(ours, theirs):.4f}), "
          f"means {_means(ours)} Cycles {_means(theirs)}")
    assert r >= LOBES_CORRELATION, r
    np.testing.assert_allclose(_means(ours), _means(theirs), rtol=LOBES_COLOUR_RTOL)
    assert [line for line in report if "Classic" in line] == [
        "material 'Classic': Mix and Add Shaders are approximated by blending their shaders' parameters"], report
    _single_lobe(monkeypatch)
    old = region(_render(bpy, scene, tmp_path, "single_lobe"))
    print(f"{fac} on the {where}, one blended lobe: correlation {correlation(old, theirs):.4f}, "
          f"means {_means(old)}")
    if fac == "checker":
        # A Fac of 0 or 1 leaves one closure per cell, which one lobe renders exactly too
        # (measured the same as ours but at the cells' anti-aliased edges).
        assert _close(old, theirs)
    else:
        assert not _close(old, theirs), "the one blended lobe must fail the tolerance"

