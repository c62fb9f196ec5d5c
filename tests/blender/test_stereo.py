"""Stereo 3D and Multi-View (issue 25) beside Cycles: each view rendered with its own camera.

A cube (a mesh) and a sphere cloud at known depths are rendered in both eyes by both engines;
the disparity of each object -- the horizontal offset of its silhouette's centre (from the
Object Index pass) between the left and the right eye -- must be Cycles' within
DISPARITY_TOLERANCE pixels for each convergence mode, and must equal the pinhole formula.
The same render with the interocular distance doubled must be outside the tolerance: the
test sees a wrong eye separation. The multilayer EXR holds both views; a Multi-View render
uses each view's own (suffixed) camera.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from blender_helpers import add_camera
from test_scene_export import INDEX, black_world, cloud_sphere, cube, lamp, principled

W, H = 128, 64
LENS, SENSOR = 50.0, 36.0
INTEROCULAR, CONVERGENCE = 0.3, 5.0
CUBE_DEPTH, SPHERE_DEPTH = 3.0, 8.0  # the centres' distances from the camera
# Measured (8 Cycles samples, 128 x 64): the cube's disparity equal to Cycles' in every mode,
# the sphere cloud's within 0.15 px (Cycles draws a cloud's points as spheres) and within
# 0.3 px of the pinhole formula; doubling the interocular distance moves them by 2.7 to 8 px.
DISPARITY_TOLERANCE = 0.5
# A stopped-render test's samples: a view takes about 0.3 s (measured: 0.085 s at 64), many
# times the core's 50 ms between progress calls.
SLOW_SAMPLES = 256


def _scene(bpy, scene, mode):
    cube(bpy, "Cube", 0.6, (-0.6, CUBE_DEPTH, 0.0), principled(bpy, "Y", (0.8, 0.7, 0.1))).pass_index = 1
    cloud_sphere(bpy, "Ball", 3000, 0.5, (0.8, SPHERE_DEPTH, 0.0), principled(bpy, "B", (0.1, 0.2, 0.9))).pass_index = 2
    lamp(bpy, "SUN", rotation=(math.radians(40), 0, math.radians(30)), energy=3.0)
    black_world(bpy, scene)
    cam = add_camera(bpy, scene, (0.0, 0.0, 0.0), (math.radians(90), 0, 0), lens=LENS, sensor_width=SENSOR,
                     sensor_fit="HORIZONTAL")
    stereo = cam.data.stereo
    stereo.convergence_mode, stereo.interocular_distance = mode, INTEROCULAR
    stereo.convergence_distance = CONVERGENCE
    r = scene.render
    r.use_multiview, r.views_format = True, "STEREO_3D"
    scene.view_layers[0].use_pass_object_index = True
    r.film_transparent = True
    c = scene.cycles
    c.samples = 8
    c.use_adaptive_sampling = c.use_denoising = False
    c.max_bounces = 0
    return cam


def _render(bpy, scene, path) -> dict:
    """{view: {pass: (H, W[, C])}} of the view layer from the multilayer multi-view EXR:
    one part per pass and view, the view in the part's 'view' attribute."""
    import OpenEXR

    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = W, H, 100
    r.image_settings.media_type = "MULTI_LAYER_IMAGE"
    r.image_settings.file_format = "OPEN_EXR_MULTILAYER"
    r.image_settings.color_depth = "32"
    r.image_settings.views_format = "MULTIVIEW"  # both views in the one file
    r.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    views: dict = {}
    for part in OpenEXR.File(str(path), separate_channels=True).parts:
        for name, c in part.channels.items():
            layer, pass_name, letter = name.split(".")
            views.setdefault(part.header["view"], {}).setdefault(pass_name, {})[letter] = c.pixels
    # Channel ids in RGBA order, upper-case or Cryptomatte's lower-case ones alike.
    order = lambda k: "RGBAXYZ".index(k.upper())  # noqa: E731
    return {view: {p: (c[next(iter(c))] if len(c) == 1 else np.stack([c[k] for k in sorted(c, key=order)], axis=-1))
                   for p, c in passes.items()}
            for view, passes in views.items()}


def _centre_x(index, value) -> float:
    """The mean column of the pixels showing object `value`."""
    cols = np.nonzero(np.rint(index) == value)[1]
    assert cols.size > 20, f"object {value} is not in the image"
    return float(cols.mean())


def _disparities(views) -> tuple:
    """(cube, sphere) horizontal disparity, left eye's centre minus right eye's, in pixels."""
    return tuple(_centre_x(views["left"][INDEX], v) - _centre_x(views["right"][INDEX], v) for v in (1, 2))


def _expected(mode, depth) -> float:
    """The pinhole disparity of a point at `depth` on the view axis: the eyes are
    INTEROCULAR apart; Off-Axis shifts each eye's image to converge at CONVERGENCE, Parallel
    does not converge, Toe-in turns each eye by atan(half interocular / convergence)."""
    focal = LENS / SENSOR * W
    if mode == "PARALLEL":
        return focal * INTEROCULAR / depth
    if mode == "OFFAXIS":
        return focal * INTEROCULAR * (1.0 / depth - 1.0 / CONVERGENCE)
    turn = math.atan(0.5 * INTEROCULAR / CONVERGENCE)
    one_eye = math.atan(0.5 * INTEROCULAR / depth) - turn
    return 2.0 * focal * math.tan(one_eye)


@pytest.mark.parametrize("mode", ["OFFAXIS", "PARALLEL", "TOE"])
def test_stereo_disparity_matches_cycles(blender, empty_scene, tmp_path, mode):
    bpy, scene = blender, empty_scene
    cam = _scene(bpy, scene, mode)
    scene.render.engine = "SPLAT_TRACER"
    ours = _render(bpy, scene, tmp_path / f"ours_{mode}.exr")
    assert set(ours) == {"left", "right"}, sorted(ours)
    assert {"Combined", INDEX} <= set(ours["left"]) and {"Combined", INDEX} <= set(ours["right"])
    cam.data.stereo.interocular_distance = 2 * INTEROCULAR
    doubled = _render(bpy, scene, tmp_path / f"doubled_{mode}.exr")
    cam.data.stereo.interocular_distance = INTEROCULAR
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    cycles = _render(bpy, scene, tmp_path / f"cycles_{mode}.exr")
    d_ours, d_doubled, d_cycles = _disparities(ours), _disparities(doubled), _disparities(cycles)
    print(f"{mode}: disparity (cube, sphere) ours {d_ours}, Cycles {d_cycles}, interocular doubled {d_doubled}")
    np.testing.assert_allclose(d_ours, d_cycles, atol=DISPARITY_TOLERANCE)
    # The sphere's silhouette is centred on its centre's image (the cube's is not: its side
    # faces show), so its disparity is the pinhole formula's.
    assert abs(d_ours[1] - _expected(mode, SPHERE_DEPTH)) < DISPARITY_TOLERANCE, (d_ours, _expected(mode, SPHERE_DEPTH))
    assert max(abs(a - b) for a, b in zip(d_doubled, d_cycles)) > 2 * DISPARITY_TOLERANCE, (d_doubled, d_cycles)
    # The eyes see different images, each with both objects lit.
    assert not np.array_equal(ours["left"]["Combined"], ours["right"]["Combined"])


def test_multiview_uses_each_views_camera(blender, empty_scene, tmp_path):
    """Multi-View: the view 'left' uses the camera named with its suffix ('Camera_L'), as
    Blender's multi-view picks it; here that camera looks elsewhere (the cube is out of its
    image), so the views differ the way Cycles' do."""
    bpy, scene = blender, empty_scene
    cam = _scene(bpy, scene, "OFFAXIS")
    r = scene.render
    r.views_format = "MULTIVIEW"
    other = cam.copy()
    other.name = "Camera_L"
    scene.collection.objects.link(other)
    other.location = (3.0, 0.0, 0.0)  # the cube at -0.6 leaves its 43-degree view
    cam.name = "Camera_R"
    bpy.context.view_layer.update()
    for view in r.views:
        view.use = view.name in ("left", "right")
    scene.render.engine = "SPLAT_TRACER"
    ours = _render(bpy, scene, tmp_path / "ours_mv.exr")
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    cycles = _render(bpy, scene, tmp_path / "cycles_mv.exr")
    for views in (ours, cycles):
        assert (np.rint(views["left"][INDEX]) == 1).sum() == 0, "the cube is outside Camera_L's view"
        assert (np.rint(views["right"][INDEX]) == 1).sum() > 20
    np.testing.assert_allclose(_centre_x(ours["left"][INDEX], 2), _centre_x(cycles["left"][INDEX], 2),
                               atol=DISPARITY_TOLERANCE)


def test_no_stereo_line_in_report(blender, empty_scene, tmp_path):
    """The report no longer says stereo is not rendered (a perspective camera's stereo is)."""
    bpy, scene = blender, empty_scene
    _scene(bpy, scene, "OFFAXIS")
    scene.render.engine = "SPLAT_TRACER"
    from blender_helpers import extension_module

    session = extension_module("blender.session")
    _render(bpy, scene, tmp_path / "report.exr")
    stats = session.HISTORY[-1]
    assert stats["views"] == ["left", "right"], stats["views"]
    assert not any("tereo" in line for line in stats["report"]), stats["report"]


def test_every_view_gets_its_cryptomatte_layers(blender, empty_scene, tmp_path):
    """Cryptomatte in a stereo render: each eye's CryptoObject layers come from that eye's
    camera -- the cube's matte (its coverage, as a compositor decodes it) sits where the
    eye's Object Index shows the cube, within DISPARITY_TOLERANCE of its centre and its
    area within 10 % (anti-aliased edges), and not where the other eye shows it (the
    cube's disparity, 7 px, is outside the tolerance) -- and the manifest, written once,
    names the scene's objects."""
    import OpenEXR

    from splat_tracer.render import cryptomatte

    bpy, scene = blender, empty_scene
    _scene(bpy, scene, "OFFAXIS")
    scene.view_layers[0].use_pass_cryptomatte_object = True
    scene.render.engine = "SPLAT_TRACER"
    path = tmp_path / "crypto.exr"
    views = _render(bpy, scene, path)
    cube_id = np.float32(cryptomatte.name_id("Cube"))
    centres = {}
    for name, passes in views.items():
        layers = sorted(p for p in passes if p.startswith("CryptoObject"))
        assert layers == ["CryptoObject00", "CryptoObject01", "CryptoObject02"], (name, sorted(passes))
        matte = sum(np.where(passes[layer][..., i] == cube_id, passes[layer][..., i + 1], 0.0)
                    for layer in layers for i in (0, 2))
        mask = np.rint(passes[INDEX]) == 1
        assert abs(matte.sum() - mask.sum()) < 0.1 * mask.sum(), (name, matte.sum(), mask.sum())
        centres[name] = float((matte.sum(axis=0) * np.arange(W)).sum() / matte.sum())
        assert abs(centres[name] - _centre_x(passes[INDEX], 1)) < DISPARITY_TOLERANCE, (name, centres)
    assert abs(centres["left"] - _centre_x(views["right"][INDEX], 1)) > 2 * DISPARITY_TOLERANCE, centres
    header = OpenEXR.File(str(path)).parts[0].header
    keys = [k for k in header if k.startswith("cryptomatte/") and k.endswith("/manifest")]
    assert len(keys) == 1, keys
    manifest = header[keys[0]]
    assert set(json.loads(manifest.decode() if isinstance(manifest, bytes) else manifest)) == {"Cube", "Ball"}


@pytest.mark.parametrize("stopped", ["left", "right"])
def test_a_view_stopped_or_never_reached_gets_no_other_views_image(blender, empty_scene, monkeypatch, stopped):
    """Esc in a stereo render, as Cycles leaves a cancelled multi-view render: the views done
    keep their image, the stopped view its samples so far, and a view never reached is left
    unwritten (black) -- never given the first view's image, which it used to get. What the
    engine writes into each view of the result is recorded at its _set_pass (headless
    Blender's Render Result has no pixels to read back, and a stopped render writes no file).
    Esc is what the engine's progress callback answers: the test's flag, raised as the
    stopped view's render starts; a view renders SLOW_SAMPLES (several times the core's 50 ms
    between progress calls) so that the stop lands within it."""
    from blender_helpers import extension_module

    bpy, scene = blender, empty_scene
    _scene(bpy, scene, "OFFAXIS")
    scene.cycles.samples = SLOW_SAMPLES
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = W, H, 100
    scene.render.engine = "SPLAT_TRACER"
    engine, session = extension_module("blender.engine"), extension_module("blender.session")
    render_scene = extension_module("render.scene").RenderScene
    written, state = {}, {"views": 0, "stop": False, "stop_at": None}
    real_set_pass, real_frame, real_render = engine._set_pass, session.render_frame, render_scene.render

    def set_pass(layer, view, name, pixels):
        written[(view, name)] = np.array(pixels)
        real_set_pass(layer, view, name, pixels)

    def render_view(self, *args, **kw):
        state["views"] += 1
        state["stop"] = state["views"] == state["stop_at"]
        return real_render(self, *args, **kw)

    def render_frame(depsgraph, method, passes=("Combined",), progress=None, **kw):
        def stop(done, total):
            progress(done, total)
            return state["stop"]
        return real_frame(depsgraph, method, passes, progress=stop, **kw)

    monkeypatch.setattr(engine, "_set_pass", set_pass)
    monkeypatch.setattr(session, "render_frame", render_frame)
    monkeypatch.setattr(render_scene, "render", render_view)
    bpy.ops.render.render()
    full = {view: written[(view, "Combined")] for view in ("left", "right")}
    assert not np.array_equal(full["left"], full["right"])

    written.clear()
    state["views"], state["stop_at"] = 0, 1 if stopped == "left" else 2
    with pytest.raises(RuntimeError, match="render stopped before the end") as error:
        bpy.ops.render.render()
    assert session.HISTORY[-1]["completed"] is False
    views = {view for view, _ in written}
    if stopped == "left":
        # The stopped first view shows its samples so far; the right eye was never rendered.
        assert views == {"left"}, sorted(written)
        assert not np.array_equal(written[("left", "Combined")], full["left"])
        assert "not rendered: view 'right'" in str(error.value)
    else:
        # The left eye finished: its whole image; the right stopped partway: its own samples,
        # not the left eye's image.
        assert views == {"left", "right"}, sorted(written)
        np.testing.assert_array_equal(written[("left", "Combined")], full["left"])
        assert not np.array_equal(written[("right", "Combined")], full["right"])
        assert not np.array_equal(written[("right", "Combined")], full["left"])
        assert "not rendered" not in str(error.value)
