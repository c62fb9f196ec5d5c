"""The material's metallic lobe of its own colour (Material.metal_colour, what a Mix Shader of
a diffuse and a glossy sets): the core shades the metallic share with it and the diffuse
share with the base colour, as the sum of the two closures."""
from __future__ import annotations

import dataclasses

import numpy as np

from splat_tracer.render.camera import Camera
from splat_tracer.render.scene import Instance
from splat_tracer.render.shading import MATERIAL_FIELDS, Light, Material

from test_scene import render, uv_sphere

RED, BLUE = (0.9, 0.1, 0.05), (0.1, 0.2, 0.8)
# A sun, direct light only: each pixel is the BSDF evaluated towards it, no sampled bounce,
# so the renders below compare to float rounding.
SUN = Light(type="SUN", power=3.0, direction=(-0.3, 0.5, -1.0))
CAMERA = Camera.look_at((0, -4, 1.5), (0, 0, 0), fov_y=35.0, aspect=1.0)


def _image(material: Material) -> np.ndarray:
    frame = render([Instance(uv_sphere(segments=48, rings=24), materials=(material,))], [SUN], cam=CAMERA,
                   w=32, h=32, samples=4, glossy_bounces=0)
    return frame.passes["Combined"][..., :3].astype(np.float64)


def test_no_metal_colour_packs_as_the_base_colours():
    row = dict(zip(MATERIAL_FIELDS, Material().pack()))
    assert (row["metal_r"], row["metal_g"], row["metal_b"], row["bump_correction"]) == (-1.0, -1.0, -1.0, 1.0)
    row = dict(zip(MATERIAL_FIELDS, Material(metal_colour=BLUE, bump_correction=False).pack()))
    assert (row["metal_r"], row["metal_g"], row["metal_b"], row["bump_correction"]) == (
        *np.float32(BLUE), 0.0)


def test_the_metallic_lobe_takes_the_metal_colour_and_the_diffuse_the_base_colour():
    metal = Material(base_colour=BLUE, metallic=1.0, roughness=0.3)
    # A full metal of another base colour but its own metal colour is that metal, exactly.
    assert np.array_equal(_image(dataclasses.replace(metal, base_colour=RED, metal_colour=BLUE)), _image(metal))
    # Half and half: the sum of half the diffuse (red, no specular layer) and half the metal (blue).
    diffuse = Material(base_colour=RED, specular_level=0.0, roughness=0.3)
    mixed = Material(base_colour=RED, metal_colour=BLUE, metallic=0.5, specular_level=0.0, roughness=0.3)
    expected = 0.5 * _image(diffuse) + 0.5 * _image(metal)
    np.testing.assert_allclose(_image(mixed), expected, rtol=1e-4, atol=1e-6)
    # The single blended lobe (base the colours' mean, metal of it) is far from that sum.
    blended = dataclasses.replace(mixed, base_colour=tuple(0.5 * (a + b) for a, b in zip(RED, BLUE)),
                                  metal_colour=None)
    assert np.abs(_image(blended) - expected).max() > 0.05
