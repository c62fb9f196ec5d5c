"""The Noise Texture node in 1, 2, 3 and 4 dimensions and its four multifractal types, side by
side with Cycles through Blender 5.0.1 (3-D fBm: test_node_materials.py).

One scene, one render per engine: eight 2 m floors in a 4 x 2 grid under an orthographic
camera looking down (60 x 60 pixels each, 240 x 120 in all), each floor's material a Noise
of its object coordinates -> Color Ramp -> Base Color, under test_node_materials' light (a sun
30 degrees off the vertical, black world, no bounces, 16 samples). Each floor's ramp spans its
two noises' 2nd to 98th percentiles (measured with the core).

Tolerances, as test_node_materials': correlation of each floor's pixels with Cycles' >= 0.95
(the issue's bar) and mean colour within 5 %. A wrong render must fall outside them: Cycles'
image of the other floor in the same column is the same material with another type (fBm,
multifractal, hybrid and hetero terrain share their first octave: their patterns correlate at
0.82 to 0.955 here, their mean colours differ by 19 % or more), any other floor another
noise field.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from blender_helpers import add_camera
from test_node_materials import COLOUR_RTOL, TEXTURE_CORRELATION, _material, correlation, plane
from test_scene_export import black_world, direct_light_only, lamp, render, stats

TILE = 60  # pixels per floor
MARGIN = 3  # pixels left out at each floor's edge (the pixel filter mixes neighbouring floors)
# name: (dimensions, type, settings, ramp from-to). The floors in a column share a dimension
# and everything but the type (and so the ramp: the union of both types' ranges), so that
# each is the other's wrong render. W, where read, is linked from the object coordinates
# (0.8 x + 0.6 y); Offset and Gain are linked from Value nodes (every input is linkable).
_PAIRS = {
    "1D": (("FBM", "HETERO_TERRAIN"), {"Detail": 1.5, "Offset": 0.6}, (0.13, 1.60)),
    "2D": (("FBM", "RIDGED_MULTIFRACTAL"), {"Distortion": 0.3, "Offset": 1.0, "Gain": 2.0}, (0.14, 1.58)),
    "3D": (("MULTIFRACTAL", "HETERO_TERRAIN"), {"Detail": 2.5, "Offset": 0.6}, (0.25, 1.80)),
    "4D": (("FBM", "HYBRID_MULTIFRACTAL"), {"Offset": 0.7, "Gain": 1.5}, (0.33, 1.69)),
}
# In the grid's order: the first types along the top row, the second along the bottom.
VARIANTS = {f"{kinds[row].lower()}_{dims.lower()}": (dims, kinds[row], settings, ramp)
            for row in (0, 1) for dims, (kinds, settings, ramp) in _PAIRS.items()}
NAMES = list(VARIANTS)


def _noise_material(bpy, name):
    dims, kind, settings, (lo, hi) = VARIANTS[name]
    m, nodes, links, shader = _material(bpy, f"Noise_{name}")
    coords = nodes.new("ShaderNodeTexCoord")
    noise = nodes.new("ShaderNodeTexNoise")
    noise.noise_dimensions, noise.noise_type = dims, kind
    # By name among all sockets: Blender hides (and keys by name skip) those the options leave unread.
    inputs = {s.name: s for s in noise.inputs}
    values = {"Scale": 3.0, "Detail": 2.0, "Roughness": 0.5, "Lacunarity": 2.0, **settings}
    for key, value in values.items():
        if key in ("Offset", "Gain"):
            source = nodes.new("ShaderNodeValue")
            source.outputs[0].default_value = value
            links.new(source.outputs[0], inputs[key])
        else:
            inputs[key].default_value = value
    if dims != "1D":
        links.new(coords.outputs["Object"], inputs["Vector"])
    if dims in ("1D", "4D"):
        w = nodes.new("ShaderNodeVectorMath")
        w.operation = "DOT_PRODUCT"
        w.inputs[1].default_value = (0.8, 0.6, 0.0)
        links.new(coords.outputs["Object"], w.inputs[0])
        links.new(w.outputs["Value"], inputs["W"])
    ramp = nodes.new("ShaderNodeValToRGB")
    ramp.color_ramp.elements[0].position, ramp.color_ramp.elements[1].position = lo, hi
    ramp.color_ramp.elements[0].color = (0.05, 0.1, 0.4, 1)
    ramp.color_ramp.elements[1].color = (0.9, 0.7, 0.1, 1)
    links.new(noise.outputs["Fac"], ramp.inputs["Fac"])
    links.new(ramp.outputs["Color"], shader.inputs["Base Color"])
    return m


def _tile(image, k):
    row, col = divmod(k, 4)
    return image[row * TILE + MARGIN:(row + 1) * TILE - MARGIN, col * TILE + MARGIN:(col + 1) * TILE - MARGIN]


@pytest.fixture(scope="module")
def renders(blender, tmp_path_factory):
    """(ours, Cycles', our report) of the eight floors, rendered once for the module."""
    bpy = blender
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "SPLAT_TRACER"
    for k, name in enumerate(NAMES):
        row, col = divmod(k, 4)
        plane(bpy, f"Floor_{name}", 2.0, (-3.0 + 2.0 * col, 1.0 - 2.0 * row, 0.0), _noise_material(bpy, name))
    add_camera(bpy, scene, (0, 0, 5), (0, 0, 0), type="ORTHO", ortho_scale=8.0)
    lamp(bpy, "SUN", rotation=(math.radians(30), 0, 0), energy=3.0)
    black_world(bpy, scene)
    direct_light_only(scene)
    c = scene.cycles
    c.samples, c.device, c.use_denoising, c.use_adaptive_sampling = 16, "CPU", False, False
    folder = tmp_path_factory.mktemp("noise")
    size = (4 * TILE, 2 * TILE)
    ours = render(bpy, scene, folder / "ours.exr", size)["ViewLayer"]["Combined"][..., :3]
    report = list(stats()["report"])
    scene.render.engine = "CYCLES"
    try:
        theirs = render(bpy, scene, folder / "cycles.exr", size)["ViewLayer"]["Combined"][..., :3]
    finally:
        scene.render.engine = "SPLAT_TRACER"
    return ours, theirs, report


@pytest.mark.parametrize("name", NAMES)
def test_noise_variant_matches_cycles(renders, name):
    ours, theirs, report = renders
    k = NAMES.index(name)
    mine, cycles = _tile(ours, k), _tile(theirs, k)
    r = correlation(mine, cycles)
    assert r >= TEXTURE_CORRELATION, r
    np.testing.assert_allclose(mine.reshape(-1, 3).mean(0), cycles.reshape(-1, 3).mean(0), rtol=COLOUR_RTOL)
    assert not [line for line in report if "Noise_" in line], report
    partner = (k + 4) % 8  # the same material with the column's other type
    off = np.abs(_tile(theirs, partner).reshape(-1, 3).mean(0) / cycles.reshape(-1, 3).mean(0) - 1).max()
    print(f"{name}: correlation {r:.4f}, mean colour off by "
          f"{np.abs(mine.reshape(-1, 3).mean(0) / cycles.reshape(-1, 3).mean(0) - 1).max():.2%}; the other type: "
          f"{correlation(_tile(theirs, partner), cycles):.3f}, {off:.0%}")
    # A wrong render -- Cycles' own of another variant, over the same coordinates (that
    # floor's) -- fails the same tolerance, by its correlation or by its mean colour.
    for j, other in enumerate(NAMES):
        if j != k:
            wrong = _tile(theirs, j)
            close = np.allclose(wrong.reshape(-1, 3).mean(0), cycles.reshape(-1, 3).mean(0), rtol=COLOUR_RTOL)
            assert correlation(wrong, cycles) < TEXTURE_CORRELATION or not close, other
