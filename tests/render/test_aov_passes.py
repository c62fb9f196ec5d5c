"""Shader AOVs through the render API: AOV Output nodes of a node program write the view
layer's AOVs on the camera ray's surfaces (native shade/aov.h), as Cycles writes them."""
import numpy as np
import pytest

from splat_tracer.render import nodes, scene, shading
from splat_tracer.render.camera import Camera

V = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
T = np.array([[0, 1, 2], [0, 2, 3]])
UV = np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]]], np.float32)
CAM = Camera.look_at((0, 0, 2), (0, 0, 0), up=(0, 1, 0), fov_y=40, aspect=1, ortho_height=2.0)
SETTINGS = shading.RenderSettings(samples=4, max_bounces=0)


def checker_aov(name="mask", alpha=None, emit_uv=False):
    """A program writing a UV checker (white/black, 2x2 cells) into the AOV `name`: Color the
    checker, Value its Fac."""
    b = nodes.Builder()
    colour, fac = b.register(width=3), b.register()
    b.emit("CHECKER", colour, fac, b.global_("UV"), b.register((1, 1, 1), 3), b.register((0, 0, 0), 3), b.register(2.0))
    b.aov(name, colour, fac)
    if alpha is not None:
        b.output("alpha", b.register(alpha))
    return b.program()


def render(instances, aovs, passes=("Combined",), threshold=0.5, settings=SETTINGS):
    rs = scene.RenderScene(instances, world=shading.World(colour=(0.2, 0.2, 0.2)))
    return rs.render(CAM, 32, 32, settings, passes=passes, aovs=aovs, aov_alpha_threshold=threshold).passes


def quadrants(img):
    return [img[4:12, 4:12].mean(axis=(0, 1)), img[4:12, 20:28].mean(axis=(0, 1)),
            img[20:28, 4:12].mean(axis=(0, 1)), img[20:28, 20:28].mean(axis=(0, 1))]


def test_colour_and_value_aovs_are_written_from_nodes():
    floor = scene.Instance(scene.Mesh(V * 2, T, corner_uv=UV), materials=(shading.Material(program=checker_aov()),))
    out = render([floor], (("mask", "COLOR"),))
    colour = out["mask"]
    assert colour.shape == (32, 32, 4)
    q = quadrants(colour)
    # Two white and two black cells; alpha 1 everywhere the floor is (it fills the view).
    assert q[0][:3] == pytest.approx(q[3][:3], abs=1e-6) and abs(q[0][0] - q[1][0]) == pytest.approx(1.0, abs=1e-6)
    np.testing.assert_allclose(colour[..., 3], 1.0)
    value = render([floor], (("mask", "VALUE"),))["mask"]
    assert value.shape == (32, 32)
    np.testing.assert_allclose(value, colour[..., 0], atol=1e-6)  # Fac is 1 on the white cells


def test_aovs_are_averaged_and_zero_where_nothing_writes():
    """A floor covering the left half: the AOV is 0 over the world and over a surface whose
    material writes no AOV; an edge pixel holds the share of its samples that met the floor."""
    half = scene.Mesh(V * [1, 2, 1] + [-1, 0, 0], T, corner_uv=UV)  # x in -2..0
    other = scene.Mesh(V * [1, 2, 1] + [1, 0, -0.1], T)  # x in 0..2, a plain material
    writes = shading.Material(program=checker_aov())
    out = render([scene.Instance(half, materials=(writes,)), scene.Instance(other)], (("mask", "COLOR"),),
                 settings=shading.RenderSettings(samples=16, max_bounces=0))
    alpha = out["mask"][..., 3]
    assert np.all(alpha[:, :15] == 1.0) and np.all(alpha[:, 17:] == 0.0) and not out["mask"][:, 17:].any()
    edge = alpha[:, 15:17]
    assert ((edge > 0.05) & (edge < 0.95)).any()  # averaged over samples, not the centre sample's


def test_an_aov_no_material_writes_is_zero_and_costs_nothing():
    floor = scene.Instance(scene.Mesh(V * 2, T, corner_uv=UV), materials=(shading.Material(program=checker_aov()),))
    plain = render([floor], ())
    out = render([floor], (("other", "COLOR"), ("level", "VALUE")))
    assert not out["other"].any() and not out["level"].any()
    np.testing.assert_array_equal(out["Combined"], plain["Combined"])
    # A wrong name does not fill the pass.
    assert not render([floor], (("Mask", "COLOR"),))["Mask"].any()


def test_combined_is_unchanged_by_aovs():
    floor = scene.Instance(scene.Mesh(V * 2, T, corner_uv=UV), materials=(shading.Material(program=checker_aov()),))
    np.testing.assert_array_equal(render([floor], (("mask", "COLOR"),))["Combined"], render([floor], ())["Combined"])


def test_transparent_surfaces_write_until_the_alpha_threshold():
    """A card of alpha 0.3 over a floor: under the threshold 0.5 the card writes its AOV and
    the floor behind it adds its own (Cycles adds every surface until one stops the camera
    ray's data passes); the threshold 0 stops at the card."""
    card = scene.Mesh(V * 2 + [0, 0, 0.5], T, corner_uv=UV)
    floor = scene.Mesh(V * 2, T, corner_uv=UV)
    b = nodes.Builder()
    b.aov("level", b.register((0, 0, 0), 3), b.register(0.25))
    b.output("alpha", b.register(0.3))
    card_mat = shading.Material(program=b.program())
    b = nodes.Builder()
    b.aov("level", b.register((0, 0, 0), 3), b.register(1.0))
    floor_mat = shading.Material(program=b.program())
    instances = [scene.Instance(card, materials=(card_mat,)), scene.Instance(floor, materials=(floor_mat,))]
    settings = shading.RenderSettings(samples=64, max_bounces=0)
    both = render(instances, (("level", "VALUE"),), settings=settings)["level"]
    # Every sample writes the card's 0.25; those passing through it (70 %) add the floor's 1.
    assert both.mean() == pytest.approx(0.25 + 0.7, abs=0.03)
    first = render(instances, (("level", "VALUE"),), threshold=0.0, settings=settings)["level"]
    np.testing.assert_allclose(first, 0.25, atol=1e-6)


def test_aov_names_are_checked():
    floor = scene.Instance(scene.Mesh(V, T))
    with pytest.raises(ValueError, match="AOV"):
        render([floor], (("Depth", "COLOR"),))
    with pytest.raises(ValueError, match="AOV"):
        render([floor], (("x", "RGB"),))
    with pytest.raises(ValueError, match="differ"):
        render([floor], (("x", "COLOR"), ("x", "VALUE")))


def test_hostile_aov_programs_are_refused():
    b = nodes.Builder()
    b.register()
    b.aov("x", 5, 0)  # a colour past the registers
    with pytest.raises(ValueError, match="AOV output out of range"):
        scene.RenderScene([scene.Instance(scene.Mesh(V, T), materials=(shading.Material(program=b.program()),))])


def test_adaptive_sampling_averages_aovs_over_each_pixels_own_samples():
    """Progressive rendering (adaptive sampling) divides each pixel's AOV sums by the samples
    it took: the same AOV as the fixed-sample render where every sample writes the same."""
    floor = scene.Instance(scene.Mesh(V * 2, T, corner_uv=UV), materials=(shading.Material(program=checker_aov()),))
    fixed = render([floor], (("mask", "COLOR"),), settings=shading.RenderSettings(samples=32, max_bounces=0))["mask"]
    adaptive = render([floor], (("mask", "COLOR"),),
                      settings=shading.RenderSettings(samples=32, max_bounces=0, adaptive=True))["mask"]
    inner = (slice(2, -2), slice(2, -2))
    np.testing.assert_allclose(adaptive[inner][..., 3], 1.0, atol=1e-6)
    np.testing.assert_allclose(adaptive[inner], fixed[inner], atol=1e-5)


def test_bad_aov_buffers_and_layouts_are_refused():
    """The core checks the AOV buffer and layout (render_arguments makes good ones): a pass
    past the buffer's channels, a width other than 1 or 4, a buffer of the wrong size."""
    floor = scene.Instance(scene.Mesh(V, T, corner_uv=UV), materials=(shading.Material(program=checker_aov()),))
    rs = scene.RenderScene([floor])
    kwargs, _ = scene.render_arguments(CAM, 8, 8, SETTINGS, scene.Method(), rs.world, aovs=(("mask", "COLOR"),),
                                       aov_names=rs.aov_names)
    block, layout, threshold = kwargs["aov"]
    for bad in ((1, 4), (0, 3)):
        with pytest.raises(ValueError, match="aov layout"):
            rs._scene.render(**dict(kwargs, aov=(block, np.array([bad], np.int32), threshold)))
    with pytest.raises(ValueError, match="aov"):
        rs._scene.render(**dict(kwargs, aov=(np.zeros((4, 8, 4), np.float32), layout, threshold)))
    with pytest.raises(ValueError, match="threshold"):
        rs._scene.render(**dict(kwargs, aov=(block, layout, 2.0)))
    rs._scene.render(**kwargs)  # the good arguments render
    assert block[..., 3].max() == 1.0
