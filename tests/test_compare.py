"""The A/B compare operator's difference image, colour management, render border and notes
(real bpy, headless), and the fixed perceptual difference scale it uses (no Blender)."""
from __future__ import annotations

import numpy as np
import pytest

from test_blender_method import cube_in_blender, image_pixels  # noqa: F401 - a fixture

from splat_tracer.render import ab, difference
from splat_tracer.render.method import Method

IMAGES = ("Splat Compare A", "Splat Compare B", "Splat Compare Difference")


# --------------------------------------------------------------------------------------
# The scale, without Blender

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


# --------------------------------------------------------------------------------------
# The operator, in real Blender

def _compare(bpy, scene, **kwargs):
    assert bpy.ops.splat_tracer.compare(**kwargs) == {"FINISHED"}
    diff = bpy.data.images[IMAGES[2]]
    return diff["splat_tracer_differing_pixels"], diff["splat_tracer_notes"]


def _png(bpy, path) -> np.ndarray:
    image = bpy.data.images.load(str(path), check_existing=False)
    try:
        return image_pixels(image)
    finally:
        bpy.data.images.remove(image)


def test_the_difference_image_is_the_fixed_scale_of_what_a_and_b_show(blender, cube_in_blender, tmp_path):
    bpy = blender
    scene = cube_in_blender[0]
    scene.render.resolution_percentage = 50
    _compare(bpy, scene, a="GENERAL", b="FULL", directory=str(tmp_path))
    shown_a, shown_b = (_png(bpy, tmp_path / f"compare_{s}.png") for s in ("a", "b"))
    expect, de = difference.difference_image(shown_a[..., :3] * shown_a[..., 3:], shown_b[..., :3] * shown_b[..., 3:])
    diff = image_pixels(bpy.data.images[IMAGES[2]])
    assert diff.shape == (120 + difference.legend_height(160), 160, 4)
    np.testing.assert_allclose(diff, expect, atol=0.6 / 255)  # a byte image
    np.testing.assert_allclose(_png(bpy, tmp_path / "compare_difference.png"), expect, atol=0.6 / 255)
    # Fringe pixels (the general method's discs against the background) are large differences.
    assert de.max() > 20 and bpy.data.images[IMAGES[2]]["splat_tracer_visible_pixels"] == (de >= 2.3).sum()


def test_a_and_b_are_saved_through_the_scenes_view_transform(blender, cube_in_blender, tmp_path):
    bpy = blender
    scene = cube_in_blender[0]
    scene.render.resolution_percentage = 50
    scene.render.image_settings.file_format = "OPEN_EXR"  # the output format is not what compare saves
    shown = {}
    for name, transform, exposure in (("standard", "Standard", 0.0), ("brighter", "Standard", 1.0),
                                      ("agx", "AgX", 0.0)):
        scene.view_settings.view_transform, scene.view_settings.exposure = transform, exposure
        _compare(bpy, scene, a="GENERAL", b="FULL", directory=str(tmp_path / name))
        shown[name] = _png(bpy, tmp_path / name / "compare_a.png")
    linear = image_pixels(bpy.data.images[IMAGES[0]])
    assert bpy.data.images[IMAGES[0]].use_view_as_render
    lit = linear[..., 3] > 0.999
    # Standard: the sRGB encoding of the scene-linear image (un-premultiplied: alpha 1 here).
    np.testing.assert_allclose(shown["standard"][..., :3][lit], difference.srgb_encode(linear[..., :3][lit]),
                               atol=1.0 / 255)
    np.testing.assert_allclose(shown["brighter"][..., :3][lit],
                               difference.srgb_encode(2.0 * linear[..., :3][lit]), atol=1.0 / 255)
    assert np.abs(shown["agx"][..., :3][lit] - shown["standard"][..., :3][lit]).max() > 0.05
    assert scene.render.image_settings.file_format == "OPEN_EXR"  # restored


@pytest.mark.parametrize("crop", [False, True])
def test_the_render_border_is_honoured(blender, cube_in_blender, crop):
    bpy = blender
    scene = cube_in_blender[0]
    r = scene.render
    r.resolution_percentage = 50
    r.use_border, r.use_crop_to_border = True, crop
    r.border_min_x, r.border_max_x, r.border_min_y, r.border_max_y = 0.25, 0.75, 0.5, 1.0
    differing, _ = _compare(bpy, scene, a="GENERAL", b="FULL")
    a, b, diff = (image_pixels(bpy.data.images[name]) for name in IMAGES)
    window = (40, 0, 80, 60)  # x0, y0 from the top, w, h of 160x120
    if crop:
        assert a.shape[:2] == (60, 80) and diff.shape[1] == 80
        inside = np.ones((60, 80), bool)
    else:
        assert a.shape[:2] == (120, 160)
        inside = np.zeros((120, 160), bool)
        x0, y0, w, h = window
        inside[y0:y0 + h, x0:x0 + w] = True
        assert (a[~inside] == 0).all() and (b[~inside] == 0).all() and (diff[:120][~inside][..., :3] == 0).all()
    assert a[inside][:, 3].max() > 0  # the cube is in the border
    changed = np.abs(a - b).max(axis=2) > 1e-3
    assert differing == changed.sum() == changed[inside].sum() > 0


def test_a_switch_that_cannot_change_the_image_says_so(blender, cube_in_blender):
    bpy = blender
    scene = cube_in_blender[0]
    scene.render.resolution_percentage = 50
    settings = scene.splat_tracer
    settings.method = "FULL"
    cube = next(o for o in scene.objects if o.type != "CAMERA")

    # The far phase on the closed cube: it shows, and no note.
    differing, notes = _compare(bpy, scene, toggle="use_far_phase")
    assert differing > 0 and notes == ""
    # The same cube marked open: the far phase cannot act, and the images are the same.
    cube.splat_tracer.closed = False
    differing, notes = _compare(bpy, scene, toggle="use_far_phase")
    assert differing == 0 and "Closed Surface" in notes and "cannot differ" in notes
    cube.splat_tracer.closed = True

    # The near phase with interpolated normals, under the headlight: nothing to see.
    differing, notes = _compare(bpy, scene, toggle="use_near_phase")
    assert differing == 0 and "headlight" in notes
    # With flat normals the chosen splat's own normal shows.
    settings.use_normal_interpolation = False
    differing, notes = _compare(bpy, scene, toggle="use_near_phase")
    assert differing > 0 and notes == ""
    # ... unless ε is 0: a layer is one disc.
    settings.epsilon = 0.0
    differing, notes = _compare(bpy, scene, toggle="use_near_phase")
    assert differing == 0 and "Epsilon 0" in notes
    # Nearest centre while the near phase is on: the same method.
    settings.epsilon, settings.use_near_phase = 1.0, True
    differing, notes = _compare(bpy, scene, toggle="use_nearest_centre")
    assert differing == 0 and "same settings" in notes
    # Normal interpolation with ε 0: one disc per layer, nothing to blend.
    settings.epsilon = 0.0
    differing, notes = _compare(bpy, scene, toggle="use_normal_interpolation")
    assert differing == 0 and "nothing to blend" in notes


def test_a_scene_without_clouds_says_the_settings_change_nothing(blender, empty_scene):
    import math
    from blender_helpers import add_camera
    bpy, scene = blender, empty_scene
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0)
    add_camera(bpy, scene, (0, -5, 0), (math.radians(90), 0, 0))
    scene.render.resolution_x, scene.render.resolution_y = 64, 48
    differing, notes = _compare(bpy, scene, a="GENERAL", b="FULL")
    assert differing == 0 and "no point cloud" in notes and "cannot differ" in notes
