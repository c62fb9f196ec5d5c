"""The A/B difference without Blender: the fixed perceptual difference scale (CIE76 ΔE, its
ramp and legend) that the compare operator and the viewport's overlay use, and the notes on
settings that cannot change the image (ab.ineffective_differences)."""
from __future__ import annotations

import numpy as np
import pytest

from splat_tracer.render import ab, difference
from splat_tracer.render.method import Method


def test_delta_e_of_known_colours():
    black, white, grey = np.zeros((1, 1, 3)), np.ones((1, 1, 3)), np.full((1, 1, 3), 0.5)
    assert difference.delta_e(black, white)[0, 0] == pytest.approx(100.0, abs=1e-3)  # L* 0 -> 100
    assert difference.delta_e(black, grey)[0, 0] == pytest.approx(53.39, abs=0.01)   # sRGB 0.5 is L* 53.39
    assert difference.delta_e(grey, grey)[0, 0] == 0.0
    # sRGB red against green: the textbook CIE76 value.
    red, green = np.array([[[1.0, 0, 0]]]), np.array([[[0, 1.0, 0]]])
    assert difference.delta_e(red, green)[0, 0] == pytest.approx(170.58, abs=0.05)


def test_the_scale_is_fixed_not_normalised_to_the_largest_difference():
    a = np.full((1, 3, 3), 0.5)
    b = a.copy()
    b[0, 1] = 0.52        # a small difference (ΔE about 0.8)
    b[0, 2] = 0.0         # a large one (grey against black)
    image, de = difference.difference_image(a, b)
    only_small = b.copy()
    only_small[0, 2] = 0.5
    image2, de2 = difference.difference_image(a, only_small)
    # The small difference has the same colour whether or not a larger one is in the image.
    np.testing.assert_array_equal(image[0, 1], image2[0, 1])
    np.testing.assert_array_equal(image[0, 0, :3], 0.0)  # identical: black
    np.testing.assert_allclose(image[0, 2, :3], difference.ramp(de[0, 2]), atol=1e-6)
    assert 0 < de[0, 1] < difference.VISIBLE < 50 < de[0, 2]
    # Each breakpoint has its colour.
    np.testing.assert_allclose(difference.ramp(np.array(difference.BREAKPOINTS)), difference.COLOURS, atol=1e-6)


def test_the_legend_shows_the_ramp_with_its_breakpoints():
    for width in (480, 320, 160, 60):
        strip = difference.legend(width)
        assert strip.shape == (difference.legend_height(width), width, 3)
        bar = strip[4]  # a row through the bar
        coloured = np.flatnonzero(bar.max(axis=1) > 0)
        assert len(coloured) > width / 2
        # Along the bar the colours run through the ramp's, in order: black ... white.
        np.testing.assert_allclose(bar[coloured[-1]], difference.COLOURS[-1], atol=0.15)
        assert bar[coloured[0]].max() < 0.05
        labels = strip[12:]
        assert (labels.max() > 0) == (width >= 130)  # the labels, when they fit
    image, _ = difference.difference_image(np.zeros((10, 200, 3)), np.zeros((10, 200, 3)))
    assert image.shape == (10 + difference.legend_height(200), 200, 4)
    np.testing.assert_array_equal(image[10:, :, :3], difference.legend(200))


def test_ineffective_differences_follow_the_visibility_logic():
    full = Method.preset("FULL")
    flat = Method.preset("FULL", normal_interpolation=False)
    from dataclasses import replace
    notes = lambda a, b, **kw: ab.ineffective_differences(a, b, **{"clouds": 1, "closed_clouds": 1,  # noqa: E731
                                                                    "headlight": False, **kw})
    assert notes(full, replace(full, far_phase=False)) == []
    assert "Closed Surface" in notes(full, replace(full, far_phase=False), closed_clouds=0)[0]
    assert "no point cloud" in notes(full, Method.preset("GENERAL"), clouds=0)[0]
    assert "cannot differ" in notes(full, Method.preset("GENERAL"), clouds=0)[-1]
    assert "Kernel" in notes(flat, replace(flat, kernel="SMOOTH"))[0]
    assert notes(full, replace(full, kernel="SMOOTH")) == []
    # The position rule: nothing to choose with ε 0; invisible to the headlight when interpolating.
    assert "Epsilon 0" in notes(replace(flat, epsilon=0.0), replace(flat, epsilon=0.0, position="FIRST"))[0]
    assert notes(flat, replace(flat, position="FIRST"), headlight=True) == []
    assert "headlight" in notes(full, replace(full, position="FIRST"), headlight=True)[0]
    assert notes(full, replace(full, position="FIRST"), headlight=False) == []
    # ε matters only to rules that use the layer.
    general = Method.preset("GENERAL")
    assert "Epsilon" in notes(general, replace(general, epsilon=2.0))[0]
    assert notes(full, replace(full, epsilon=2.0)) == []
    # Two differences, one of which shows: no "cannot differ".
    mixed = notes(full, replace(full, far_phase=False, wrong_hit_elimination=False), closed_clouds=0)
    assert len(mixed) == 1 and "cannot differ" not in mixed[0]
    assert "same settings" in notes(full, full)[0]
