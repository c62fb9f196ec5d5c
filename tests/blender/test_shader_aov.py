"""Shader AOVs (issue 26, item 3) through Blender, side by side with Cycles: the view layer's
AOVs written by the materials' AOV Output nodes, read back from the multilayer EXR under
the AOV's name (a colour AOV as RGBA, a value AOV as one channel, as Cycles writes them).

The scenes of test_node_materials.py: an orthographic view from above, 80x80 pixels, 16
samples, a sun, no bounces. Tolerances (measured with bpy 5.0.1):
- AOV_CORRELATION = 0.95: Pearson correlation per pixel with Cycles' AOV (measured: the
  Checker 0.9987, the scan's luminance 0.9981); a checker one cell off correlates below 0.
- AOV_ATOL = 0.005: mean AOV value per region against Cycles' and against the value
  computed here (AOVs carry no lighting; measured: the scan's halves within 3e-5 of Cycles').
  The halves' luminances differ by 0.023: swapped, they fail.
"""
from __future__ import annotations

import numpy as np
import pytest

from test_node_materials import HALVES, SIZE, _flat_cloud, _setup, correlation, plane
from test_scene_export import render_both, stats

AOV_CORRELATION = 0.95
AOV_ATOL = 0.005
LUMINANCE = (0.2126729, 0.7151522, 0.0721750)  # Blender's default (Rec. 709) RGB to BW


def _aov(scene, name, kind):
    aov = scene.view_layers[0].aovs.add()
    aov.name, aov.type = name, kind
    return aov


def _both(bpy, scene, tmp_path, name):
    """(ours, Cycles') passes of the view layer, and our report."""
    return render_both(bpy, scene, tmp_path, name, (SIZE, SIZE))


def _checker_floor(bpy, aov_name="Mask"):
    """A floor lit grey, whose AOV Output writes a UV Checker (4 cells a side) as `aov_name`'s
    Color, and whose second AOV Output, named 'mask' (no AOV of the view layer), writes 1."""
    m = bpy.data.materials.new("Checkered")
    nodes, links = m.node_tree.nodes, m.node_tree.links
    coords, checker = nodes.new("ShaderNodeTexCoord"), nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 4.0
    checker.inputs["Color1"].default_value = (0.9, 0.8, 0.2, 1)
    checker.inputs["Color2"].default_value = (0.1, 0.2, 0.6, 1)
    links.new(coords.outputs["UV"], checker.inputs["Vector"])
    out = nodes.new("ShaderNodeOutputAOV")
    out.aov_name = aov_name
    links.new(checker.outputs["Color"], out.inputs["Color"])
    stray = nodes.new("ShaderNodeOutputAOV")
    stray.aov_name = "mask"  # names are case-sensitive: this one writes nothing here
    stray.inputs["Value"].default_value = 1.0
    plane(bpy, "Floor", 2.0, (0, 0, 0), m)
    return out


def test_a_colour_aov_from_a_checker_matches_cycles(blender, empty_scene, tmp_path):
    bpy, scene = blender, empty_scene
    _checker_floor(bpy)
    _aov(scene, "Mask", "COLOR")
    _aov(scene, "Unused", "VALUE")  # no material writes it: 0 everywhere
    _setup(bpy, scene)
    ours, theirs, report = _both(bpy, scene, tmp_path, "checker_aov")
    mine, cycles = ours["Mask"], theirs["Mask"]
    assert mine.shape == cycles.shape == (SIZE, SIZE, 4)
    r = correlation(mine[..., :3], cycles[..., :3])
    assert r >= AOV_CORRELATION, r
    assert correlation(np.roll(mine[..., :3], SIZE // 4, axis=1), cycles[..., :3]) < 0, "a cell off must fail"
    # Each cell's colour, unlit (the AOV is the node's value), as Cycles writes it; the
    # checker's corner cell (image top left: UV (0, 1)) is Color1, as 4 cells make it.
    cell = SIZE // 4
    for i in range(4):
        for j in range(4):
            region = (slice(i * cell + 4, (i + 1) * cell - 4), slice(j * cell + 4, (j + 1) * cell - 4))
            want = (0.9, 0.8, 0.2, 1.0) if (i + j) % 2 == 0 else (0.1, 0.2, 0.6, 1.0)
            mean = mine[region].reshape(-1, 4).mean(0)
            np.testing.assert_allclose(mean, want, atol=AOV_ATOL)
            np.testing.assert_allclose(mean, cycles[region].reshape(-1, 4).mean(0), atol=AOV_ATOL)
    # Alpha 1 where every sample met the floor (its outermost pixels' filter reaches past it).
    np.testing.assert_allclose(mine[2:-2, 2:-2, 3], 1.0)
    assert not ours["Unused"].any() and not theirs["Unused"].any()
    assert not [line for line in report if "AOV" in line], report


def test_a_wrong_aov_name_fills_nothing(blender, empty_scene, tmp_path):
    """The node names 'Mask ' (a trailing space): the view layer's 'Mask' stays 0, as in
    Cycles -- and the comparison above would fail it."""
    bpy, scene = blender, empty_scene
    _checker_floor(bpy, aov_name="Mask ")
    _aov(scene, "Mask", "COLOR")
    _setup(bpy, scene)
    ours, theirs, _ = _both(bpy, scene, tmp_path, "wrong_name")
    assert not ours["Mask"].any() and not theirs["Mask"].any()
    with pytest.raises(AssertionError):
        np.testing.assert_allclose(ours["Mask"][2:-2, 2:-2, 3], 1.0)


def test_a_value_aov_of_the_point_colours_luminance_matches_cycles(blender, empty_scene, tmp_path):
    """A scan: Color Attribute -> RGB to BW -> AOV Output's Value ('Luma'); its surface is the
    points' colours emitted."""
    bpy, scene = blender, empty_scene
    m = bpy.data.materials.new("Scan")
    nodes, links = m.node_tree.nodes, m.node_tree.links
    nodes.remove(nodes["Principled BSDF"])
    emission, attribute, bw = (nodes.new(t) for t in ("ShaderNodeEmission", "ShaderNodeVertexColor",
                                                       "ShaderNodeRGBToBW"))
    attribute.layer_name = "splat_color"
    out = nodes.new("ShaderNodeOutputAOV")
    out.aov_name = "Luma"
    links.new(attribute.outputs["Color"], bw.inputs["Color"])
    links.new(bw.outputs["Val"], out.inputs["Value"])
    links.new(attribute.outputs["Color"], emission.inputs["Color"])
    links.new(emission.outputs["Emission"], nodes["Material Output"].inputs["Surface"])
    _flat_cloud(bpy, m)
    _aov(scene, "Luma", "VALUE")
    _setup(bpy, scene)
    ours, theirs, report = _both(bpy, scene, tmp_path, "luma_aov")
    mine, cycles = ours["Luma"], theirs["Luma"]
    assert mine.shape == cycles.shape == (SIZE, SIZE)
    for half, colour in enumerate(HALVES):
        cols = slice(8, 30) if half == 0 else slice(50, 72)
        want = float(np.dot(colour, LUMINANCE))
        assert mine[25:55, cols].mean() == pytest.approx(want, abs=AOV_ATOL)
        assert mine[25:55, cols].mean() == pytest.approx(cycles[25:55, cols].mean(), abs=AOV_ATOL)
    assert correlation(mine[..., None], cycles[..., None]) >= AOV_CORRELATION
    # The two halves' luminances differ by more than the tolerance: swapping them would fail.
    assert abs(np.dot(HALVES[0], LUMINANCE) - np.dot(HALVES[1], LUMINANCE)) > 2 * AOV_ATOL
    assert not [line for line in report if "AOV" in line], report


def test_transparent_surfaces_add_their_aovs_until_the_alpha_threshold_as_in_cycles(blender, empty_scene,
                                                                                   tmp_path):
    """Cycles writes AOVs on every surface the camera ray passes through until one whose alpha
    reaches the view layer's Alpha Threshold (0.5), each adding its value. A card writing 0.25
    over a floor writing 1: fully transparent, 1.25 in every sample; of alpha 0.3 at the
    threshold 0.2, the card stops it (0.25); of alpha 0.3 at 0.5, the floor adds its 1 in the
    samples that pass the card -- 70 % here, 74 % in Cycles, which passes a partly transparent
    surface with probability (1 - alpha) / ((1 - alpha) + alpha x its BSDF's sampling weight)
    (docs/user-guide.md, Passes)."""
    bpy, scene = blender, empty_scene

    def writer(name, value, alpha):
        m = bpy.data.materials.new(name)
        nodes = m.node_tree.nodes
        nodes["Principled BSDF"].inputs["Alpha"].default_value = alpha
        out = nodes.new("ShaderNodeOutputAOV")
        out.aov_name = "Level"
        out.inputs["Value"].default_value = value
        return m

    plane(bpy, "Floor", 2.0, (0, 0, 0), writer("Ground", 1.0, 1.0))
    veil = writer("Veil", 0.25, 0.0)
    plane(bpy, "Card", 2.0, (0, 0, 0.5), veil)
    _aov(scene, "Level", "VALUE")
    _setup(bpy, scene)
    scene.cycles.samples, scene.cycles.transparent_max_bounces = 64, 8
    inner = (slice(4, -4), slice(4, -4))

    def means(name):
        ours, theirs, _ = _both(bpy, scene, tmp_path, name)
        return float(ours["Level"][inner].mean()), float(theirs["Level"][inner].mean())

    assert means("clear") == pytest.approx((1.25, 1.25), abs=1e-4)  # both surfaces add
    veil.node_tree.nodes["Principled BSDF"].inputs["Alpha"].default_value = 0.3
    scene.view_layers[0].pass_alpha_threshold = 0.2
    assert means("stops") == pytest.approx((0.25, 0.25), abs=1e-4)  # the card stops the writes
    scene.view_layers[0].pass_alpha_threshold = 0.5
    mine, cycles = means("veil")
    assert mine == pytest.approx(0.25 + 0.7, abs=0.02) and cycles == pytest.approx(0.25 + 0.743, abs=0.02)


def test_aovs_survive_denoising_in_every_stereo_view(blender, empty_scene, tmp_path):
    """A stereo render with Cycles' Denoise on: each eye's EXR view has the AOV, drawn from that
    eye's camera (the cube's mask moves with its Object Index silhouette between the eyes) and
    kept through the denoiser's cut of the passes."""
    from test_stereo import INDEX, _render, _scene

    bpy, scene = blender, empty_scene
    _scene(bpy, scene, "PARALLEL")
    out = bpy.data.materials["Y"].node_tree.nodes.new("ShaderNodeOutputAOV")
    out.aov_name, out.inputs["Value"].default_value = "Cube", 1.0
    _aov(scene, "Cube", "VALUE")
    scene.cycles.use_denoising = True
    scene.render.engine = "SPLAT_TRACER"
    views = _render(bpy, scene, tmp_path / "stereo_aov.exr")
    assert set(views) == {"left", "right"}, sorted(views)
    for name, passes in views.items():
        assert "Cube" in passes, (name, sorted(passes))
        cube = np.rint(passes[INDEX]) == 1
        assert cube.sum() > 20, name
        # The AOV is 1 where the cube is: the Object Index is the pixel centre's, the AOV the
        # 8 samples' average, so a pixel next to the silhouette may lose a sample (1/8).
        inner = cube & np.roll(cube, 1, 0) & np.roll(cube, -1, 0) & np.roll(cube, 1, 1) & np.roll(cube, -1, 1)
        np.testing.assert_allclose(passes["Cube"][inner], 1.0, atol=0.126)
        assert passes["Cube"][inner].mean() > 0.99, name
        assert not passes["Cube"][np.rint(passes[INDEX]) == 2].any(), "the sphere writes no AOV"
    # Each view its own camera: the masks differ between the eyes.
    assert not np.array_equal(views["left"]["Cube"], views["right"]["Cube"])
    assert not [line for line in stats()["report"] if "AOV" in line]
