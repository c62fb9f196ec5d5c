"""A Diffuse mixed with a Glossy (the classic Cycles material), side by side with Cycles: the
Mix keeps the two closures' lobes apart (the diffuse of its colour, a GGX metallic lobe of
the Glossy's colour and roughness), rather than one lobe of blended colour and roughness.

Scenes: the Mix Shader of a red Diffuse BSDF and a grey Glossy BSDF (roughness 0.3), by a UV
Checker's Fac and by a Fresnel's (the classic), on a 2 m floor seen from above (a sun, a
black world, no bounces: test_node_materials' scene) and on a sphere on a floor seen at an
angle under a sun and a bright world (one glossy bounce: the world in the reflection).

Tolerances (measured with bpy 5.0.1, printed by each test):
- LOBES_CORRELATION = 0.98: Pearson correlation of the pixels' channel means with Cycles'.
- LOBES_COLOUR_RTOL = 0.05: relative difference of the mean colour, per channel.
Each test renders the old single-lobe blend too and asserts that it fails them.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from blender_helpers import add_camera, extension_module
from test_mix_shader_cycles import RED, _checker_fac, _mix_material
from test_node_materials import SIZE, _setup, correlation, plane
from test_scene_export import lamp, render, stats, uv_sphere

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


FACS = {"checker": _checker_fac, "fresnel": _fresnel_fac}


def _sphere_scene(bpy, scene, material):
    """A sphere of `material` on a grey diffuse floor, seen at an angle, a sun and a bright
    world; one glossy bounce (the world and the floor in the reflection), 64 samples."""
    floor = bpy.data.materials.new("Floor")
    floor.node_tree.nodes["Principled BSDF"].inputs["Specular IOR Level"].default_value = 0.0
    floor.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 1.0
    plane(bpy, "Floor", 6.0, (0, 0, 0), floor)
    uv_sphere(bpy, "Ball", 0.8, (0, 0, 0.8), material, smooth=True)
    add_camera(bpy, scene, (0, -4.2, 2.4), (math.radians(65), 0, 0))
    lamp(bpy, "SUN", rotation=(math.radians(35), 0, math.radians(30)), energy=3.0)
    scene.world = bpy.data.worlds.new("Sky")
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.6, 0.7, 0.9, 1)
    c = scene.cycles
    c.max_bounces, c.diffuse_bounces, c.glossy_bounces, c.transmission_bounces = 1, 0, 1, 0
    c.transparent_max_bounces = 0
    c.samples, c.device, c.use_denoising, c.use_adaptive_sampling = 64, "CPU", False, False


def _render(bpy, scene, tmp_path, name):
    return render(bpy, scene, tmp_path / f"{name}.exr", (SIZE, SIZE))["ViewLayer"]["Combined"][..., :3]


def _single_lobe(monkeypatch):
    """The old blend: one lobe of blended colour, metallic and roughness (the split left out
    of both the constant and the per-shading-point blend)."""
    monkeypatch.setattr(extension_module("blender.export.shading"), "_split_lobes", lambda *a: {})
    monkeypatch.setattr(extension_module("blender.export.shader_mix")._Blender, "_split_lobes", lambda *a: None)


def _means(image):
    return image.reshape(-1, 3).mean(0)


def _close(ours, theirs) -> bool:
    return (correlation(ours, theirs) >= LOBES_CORRELATION and
            np.allclose(_means(ours), _means(theirs), rtol=LOBES_COLOUR_RTOL, atol=0.0))


@pytest.mark.parametrize("where", ["floor", "sphere"])
@pytest.mark.parametrize("fac", ["checker", "fresnel"])
def test_a_diffuse_mixed_with_a_glossy_matches_cycles(blender, empty_scene, tmp_path, monkeypatch, fac, where):
    bpy, scene = blender, empty_scene
    material, _ = _mix_material(bpy, "Classic", _diffuse_bsdf, _glossy, FACS[fac])
    if where == "floor":
        plane(bpy, "Floor", 2.0, (0, 0, 0), material)
        _setup(bpy, scene)
    else:
        _sphere_scene(bpy, scene, material)
    ours = _render(bpy, scene, tmp_path, "ours")
    report = list(stats()["report"])
    scene.render.engine = "CYCLES"
    try:
        theirs = _render(bpy, scene, tmp_path, "cycles")
    finally:
        scene.render.engine = "SPLAT_TRACER"
    r = correlation(ours, theirs)
    print(f"{fac} on the {where}: correlation {r:.4f}, means {_means(ours)} Cycles {_means(theirs)}")
    assert r >= LOBES_CORRELATION, r
    np.testing.assert_allclose(_means(ours), _means(theirs), rtol=LOBES_COLOUR_RTOL)
    assert [line for line in report if "Classic" in line] == [
        "material 'Classic': Mix and Add Shaders are approximated by blending their shaders' parameters"], report
    _single_lobe(monkeypatch)
    old = _render(bpy, scene, tmp_path, "single_lobe")
    print(f"{fac} on the {where}, one blended lobe: correlation {correlation(old, theirs):.4f}, "
          f"means {_means(old)}")
    assert not _close(old, theirs), "the one blended lobe must fail the tolerance"

