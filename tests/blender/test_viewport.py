"""The viewport's Rendered mode without a GPU (real bpy, headless): the view -> camera
conversion checked against Blender's own view math (bpy_extras.view3d_utils), the update
logic (what is exported and built after which change, by the session's counters), and the
progressive passes converging to the F12 image. Only engine._draw_pixels (gpu) is untested.

Headless Blender has no drawn 3D view, so its RegionView3D matrices are not computed; the
tests build them as Blender does (a camera's projection for the region, the view matrix the
inverse of the view's world matrix, the camera view's zoom and offset applied to the view
plane) and give them to view3d_utils through stand-ins carrying window_matrix, view_matrix,
perspective_matrix, is_perspective and view_perspective, as RegionView3D does."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from blender_helpers import add_camera, extension_module
from test_scene_export import cloud_sphere, cube, lamp, principled

RW, RH = 64, 48  # region size


def _stand_ins(window_matrix, view_matrix, perspective: bool, kind: str, width=RW, height=RH):
    region = SimpleNamespace(width=width, height=height)
    rv3d = SimpleNamespace(window_matrix=window_matrix, view_matrix=view_matrix,
                           perspective_matrix=window_matrix @ view_matrix, is_perspective=perspective,
                           view_perspective=kind)
    return region, rv3d


def _blender_rays(region, rv3d):
    """view3d_utils' ray (origin, direction) through each pixel centre, top row first."""
    from bpy_extras import view3d_utils
    o, d = [], []
    for i in range(region.height):
        for j in range(region.width):
            coord = (j + 0.5, region.height - (i + 0.5))
            o.append(tuple(view3d_utils.region_2d_to_origin_3d(region, rv3d, coord)))
            d.append(tuple(view3d_utils.region_2d_to_vector_3d(region, rv3d, coord)))
    return np.array(o), np.array(d)


def _assert_same_rays(camera, region, rv3d):
    ours_o, ours_d = camera.rays(region.width, region.height)
    theirs_o, theirs_d = _blender_rays(region, rv3d)
    np.testing.assert_allclose(ours_d, theirs_d, atol=2e-5)
    # Same line: our origin (on the near plane) lies on Blender's ray.
    offset = ours_o.astype(np.float64) - theirs_o
    along = np.einsum("ij,ij->i", offset, theirs_d)[:, None] * theirs_d
    assert np.abs(offset - along).max() < 1e-4 * max(1.0, np.abs(offset).max())


def _view_camera(bpy, scene, kind="PERSP", shift=(0.0, 0.0), **settings):
    """A camera object standing in for the 3D view: its world matrix is the view's inverse
    view matrix, its projection at the region size the view's window matrix (Blender builds
    both from the same view plane)."""
    cam = add_camera(bpy, scene, (3.0, -4.0, 2.5), (math.radians(65), 0, math.radians(35)), type=kind,
                     shift_x=shift[0], shift_y=shift[1], **settings)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    window = cam.calc_matrix_camera(depsgraph, x=RW, y=RH)
    return cam, window, cam.matrix_world.inverted()


@pytest.mark.parametrize("kind", ["PERSP", "ORTHO"])
def test_view_rays_are_blenders_for_perspective_and_orthographic_views(blender, empty_scene, kind):
    from splat_tracer.blender import viewport
    cam, window, view = _view_camera(blender, empty_scene, kind, shift=(0.1, -0.05), lens=35, ortho_scale=5)
    region, rv3d = _stand_ins(window, view, kind == "PERSP", kind)
    _assert_same_rays(viewport.camera_from_view(window, view), region, rv3d)


def _camera_view_window(window, zoom: float, offset: tuple):
    """The camera view's window matrix at a zoom factor and offset: Blender scales the view
    plane by 1/zoom and moves it by the offset (BKE_camera_params_compute_viewplane), which
    in normalised device coordinates is x' = zoom * x - offset (applied to clip space)."""
    from mathutils import Matrix
    a = Matrix(((zoom, 0, 0, -offset[0]), (0, zoom, 0, -offset[1]), (0, 0, 1, 0), (0, 0, 0, 1)))
    return a @ window


def test_camera_view_with_zoom_and_offset_sees_the_f12_image_in_its_frame(blender, empty_scene):
    from splat_tracer.blender import export, viewport
    from splat_tracer.render.camera import Camera
    scene = empty_scene
    scene.render.resolution_x, scene.render.resolution_y = 160, 120  # the region's aspect
    cam, window, view = _view_camera(blender, scene, "PERSP", shift=(0.05, 0.0), lens=40)
    zoom, offset = 0.6, (0.1, -0.15)
    cv_window = _camera_view_window(window, zoom, offset)
    region, rv3d = _stand_ins(cv_window, view, True, "CAMERA")
    camera = viewport.camera_from_view(cv_window, view)
    _assert_same_rays(camera, region, rv3d)

    # The camera frame in the region: where Blender draws it, computed from the camera's frame.
    depsgraph = blender.context.evaluated_depsgraph_get()
    frame = [tuple(cam.matrix_world @ v) for v in cam.data.view_frame(scene=scene)]
    rect = viewport.region_rect(rv3d.perspective_matrix, frame, RW, RH)
    expect = [((-zoom - offset[0]) + 1) / 2 * RW, ((-zoom - offset[1]) + 1) / 2 * RH,
              ((zoom - offset[0]) + 1) / 2 * RW, ((zoom - offset[1]) + 1) / 2 * RH]
    np.testing.assert_allclose(rect, expect, atol=1e-3)

    # Within the frame, the view's rays are the F12 camera's at the same place of its image.
    f12 = export.export_camera(depsgraph, 160, 120, (0, 0, 0))
    x0, y0, x1, y1 = rect
    fx, fy = np.meshgrid(np.linspace(0.1, 0.9, 5), np.linspace(0.1, 0.9, 5))
    u, v = x0 + fx * (x1 - x0), y0 + fy * (y1 - y0)  # region pixels, bottom-left origin

    def directions(cam_: Camera, ndc_x, ndc_y):
        left, right, bottom, top = cam_.frustum
        u = left + (right - left) * (ndc_x.ravel() + 1) / 2
        v = bottom + (top - bottom) * (ndc_y.ravel() + 1) / 2
        d = np.column_stack([u, v, -np.ones_like(u)]) @ cam_.local_from_camera[:3, :3].T
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    np.testing.assert_allclose(directions(camera, 2 * u / RW - 1, 2 * v / RH - 1),
                               directions(f12, 2 * fx - 1, 2 * fy - 1), atol=1e-6)

    # The scene's render border, in the camera view, is a part of the frame.
    window_px = viewport.border_window(RW, RH, rect, (0.25, 0.5, 0.75, 1.0))
    wx0, wy0, ww, wh = window_px
    assert abs(wx0 - (x0 + 0.25 * (x1 - x0))) <= 0.5 and abs(wx0 + ww - (x0 + 0.75 * (x1 - x0))) <= 0.5
    assert abs((RH - wy0) - y1) <= 0.5 and abs((RH - wy0 - wh) - (y0 + 0.5 * (y1 - y0))) <= 0.5


def test_border_window():
    from splat_tracer.blender import viewport
    assert viewport.border_window(100, 50) == (0, 0, 100, 50)
    # A view's render border: fractions of the region, rows counted from the top.
    assert viewport.border_window(100, 50, None, (0.1, 0.2, 0.5, 1.0)) == (10, 0, 40, 40)
    assert viewport.border_window(100, 50, (200, 0, 300, 50), (0.0, 0.0, 1.0, 1.0)) is None  # off the region


def test_pass_schedule_ends_with_the_scenes_samples():
    from splat_tracer.blender import viewport
    assert viewport.pass_schedule(16) == [(4, 1), (1, 1), (1, 4), (1, 16)]
    assert viewport.pass_schedule(1) == [(4, 1), (1, 1)]
    assert viewport.pass_schedule(20)[-1] == (1, 20)
    # A large view: the first pass stays near COARSE_PIXELS, halved divisors follow.
    big = viewport.pass_schedule(16, pixels=1280 * 720)
    assert big == [(7, 1), (3, 1), (1, 1), (1, 4), (1, 16)]
    assert (1280 / 7) * (720 / 7) <= viewport.COARSE_PIXELS
    assert viewport.pass_schedule(16, pixels=80 * 60) == viewport.pass_schedule(16)  # small: unchanged


# --------------------------------------------------------------------------------------
# The session: what is rebuilt after which change, and the passes.

def _scene(bpy, scene):
    grey = principled(bpy, "Grey")
    ball = cloud_sphere(bpy, "Ball", 3000, 0.6, (-0.8, 0, 0), grey)
    box = cube(bpy, "Box", 1.0, (0.8, 0, 0), grey)
    sun = lamp(bpy, "SUN", rotation=(math.radians(30), 0, 0), energy=3.0)
    add_camera(bpy, scene, (0, -6, 0), (math.radians(90), 0, 0))
    scene.render.resolution_x, scene.render.resolution_y = 80, 60
    scene.cycles.samples = scene.cycles.preview_samples = 4
    return grey, ball, box, sun


class _Recorder:
    """depsgraph.updates exist only inside the update handler: it classifies them there."""

    def __init__(self, bpy):
        self.bpy = bpy
        self.changes = None

    def __enter__(self):
        self.bpy.app.handlers.depsgraph_update_post.append(self)
        return self

    def __exit__(self, *exc):
        self.bpy.app.handlers.depsgraph_update_post.remove(self)

    def __call__(self, scene, depsgraph):
        viewport = extension_module("blender.viewport")
        found = viewport.classify(depsgraph.updates)
        if self.changes is None:
            self.changes = found
        else:
            self.changes.export |= found.export
            self.changes.settings |= found.settings
            self.changes.reasons += found.reasons

    def apply(self, session, change, scene_setting=False):
        """Makes `change`, lets Blender evaluate it, and tells the session what changed."""
        self.changes = None
        change()
        self.bpy.context.view_layer.update()
        changes = self.changes
        if changes is None and scene_setting:
            # Editing an add-on property in the UI tags the scene (a Scene-only update, as
            # test_a_scene_setting_is_a_settings_change shows with a built-in property); a
            # script's setattr of an add-on property tags nothing in Blender 5.0, and
            # scene.update_tag() would tag every object too. So: what the UI's update gives.
            changes = extension_module("blender.viewport").Changes(settings=True, reasons=["scene settings"])
        before = dict(session.counters)
        session.update(self.bpy.context.evaluated_depsgraph_get(), changes)
        session.refine()
        return changes, {k: session.counters[k] - before[k] for k in before}


def _assert_same_to_rounding(view_image, f12_image):
    """The same rays, samples and seed, but the view's rays come from the float32 window
    matrix and F12's from the camera's parameters in double: they agree to float rounding,
    so a ray that grazes a splat's edge may pick another splat and its path another
    colour (measured: 1 pixel of 4,800). Every other pixel is equal to 1e-4."""
    off = (np.abs(view_image - f12_image) > 1e-4).any(axis=-1)
    assert off.mean() <= 0.002, off.sum()


def _f12_view(bpy, scene, width, height):
    viewport = extension_module("blender.viewport")
    depsgraph = bpy.context.evaluated_depsgraph_get()
    cam = scene.camera.evaluated_get(depsgraph)
    window = cam.calc_matrix_camera(depsgraph, x=width, y=height)
    view = np.linalg.inv(np.array(cam.matrix_world.normalized(), np.float64))
    return viewport.View.of(window, view, width, height, clip=(cam.data.clip_start, cam.data.clip_end))


def test_each_change_rebuilds_only_what_it_must(blender, empty_scene):
    viewport = extension_module("blender.viewport")
    bpy, scene = blender, empty_scene
    grey, ball, box, sun = _scene(bpy, scene)
    session = viewport.ViewportSession()
    with _Recorder(bpy) as rec:
        bpy.context.view_layer.update()
        session.set_view(_f12_view(bpy, scene, 80, 60))
        session.update(bpy.context.evaluated_depsgraph_get())  # the first view_update
        session.refine()
        assert session.counters["exports"] == 1 and session.counters["geometry_builds"] == 2
        passes = len(viewport.pass_schedule(4))
        assert session.counters["renders"] == passes

        # The view only: re-rendered, nothing exported.
        before = dict(session.counters)
        other = _f12_view(bpy, scene, 80, 60)
        moved = np.array(other.view_matrix)
        moved[0, 3] += 0.2  # the view slides sideways
        session.set_view(viewport.View.of(other.window_matrix, moved, 80, 60))
        session.refine()
        assert session.counters["exports"] == before["exports"]
        assert session.counters["renders"] - before["renders"] == passes

        def delta_of(change, scene_setting=False):
            return rec.apply(session, change, scene_setting)

        # Settings: re-rendered without export.
        for change in (lambda: setattr(scene.splat_tracer, "epsilon", 0.5),
                       lambda: setattr(scene.splat_tracer, "use_far_phase", False),
                       lambda: setattr(scene.splat_tracer, "shadow_samples", 2),
                       lambda: setattr(scene.render, "filter_size", 2.0)):
            changes, delta = delta_of(change, scene_setting=True)
            assert changes.settings and not changes.export, changes.reasons
            assert delta["exports"] == 0 and delta["geometry_builds"] == 0 and delta["renders"] == passes
        changes, delta = delta_of(lambda: setattr(scene.cycles, "preview_samples", 16), scene_setting=True)
        assert delta["exports"] == 0 and delta["renders"] == len(viewport.pass_schedule(16))

        # A material, a lamp, a transform: exported again, no geometry built.
        shader = grey.node_tree.nodes["Principled BSDF"]
        for change in (lambda: setattr(shader.inputs["Base Color"], "default_value", (0.8, 0.2, 0.2, 1)),
                       lambda: setattr(sun.data, "energy", 5.0),
                       lambda: setattr(sun, "rotation_euler", (math.radians(40), 0, 0)),
                       lambda: setattr(box, "location", (0.9, 0, 0))):
            changes, delta = delta_of(change)
            assert changes.export, changes.reasons
            assert delta["exports"] == 1 and delta["geometry_builds"] == 0, changes.reasons

        # Editing one object: only its geometry is built.
        def edit_box():
            box.data.vertices[0].co.z += 0.2
            box.data.update()
        changes, delta = delta_of(edit_box)
        assert delta["exports"] == 1 and delta["geometry_builds"] == 1, changes.reasons

        # Hiding an object (a Scene-only update): exported again, nothing built.
        changes, delta = delta_of(lambda: box.hide_set(True))
        assert changes.settings and not changes.export, changes.reasons  # Blender says only "Scene"
        assert delta["exports"] == 1 and delta["geometry_builds"] == 0
        assert session.exported.meshes == 0 and session.exported.clouds == 1

        # The radius factor is baked into the clouds' splats: the cloud is rebuilt (only it).
        changes, delta = delta_of(lambda: setattr(scene.splat_tracer, "radius_factor", 1.2), scene_setting=True)
        assert delta["exports"] == 1 and delta["geometry_builds"] == 1

        # Nothing that matters (the selection): nothing at all.
        changes, delta = delta_of(lambda: ball.select_set(True))
        assert not changes.export, changes.reasons  # Blender reports the Scene: settings read, unchanged
        assert delta == {"exports": 0, "geometry_builds": 0, "renders": 0, "restarts": 0}
    session.close()


def test_progressive_passes_converge_to_the_f12_image(blender, empty_scene):
    viewport, session_module = extension_module("blender.viewport"), extension_module("blender.session")
    bpy, scene = blender, empty_scene
    _scene(bpy, scene)
    scene.cycles.samples = scene.cycles.preview_samples = 8
    bpy.context.view_layer.update()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    f12 = session_module.render_frame(depsgraph, scene.splat_tracer.core_method()).passes["Combined"]

    vs = viewport.ViewportSession()
    vs.set_view(_f12_view(bpy, scene, 80, 60))
    vs.update(depsgraph)
    images = []
    while vs.step():
        images.append(vs.latest())
    images.append(vs.latest())
    assert [(im.scale, im.samples) for im in images] == [(4, 1), (1, 1), (1, 4), (1, 8)]
    coarse = images[0].pixels
    assert coarse.shape == (60, 80, 4)
    # The coarse pass is 20x15 pixels upscaled: blocks of 4x4 equal pixels.
    assert np.array_equal(coarse[::4, ::4].repeat(4, 0).repeat(4, 1), coarse)
    assert images[-1].final and not images[-2].final
    errors = [np.abs(im.pixels - f12).mean() for im in images]
    assert errors[-1] < 1e-6 and errors[-1] <= min(errors[:-1])
    _assert_same_to_rounding(images[-1].pixels, f12)
    vs.close()


def test_a_border_renders_only_its_window(blender, empty_scene):
    viewport = extension_module("blender.viewport")
    bpy, scene = blender, empty_scene
    _scene(bpy, scene)
    bpy.context.view_layer.update()
    full = _f12_view(bpy, scene, 80, 60)
    window = viewport.border_window(80, 60, None, (0.25, 0.5, 0.75, 1.0))
    vs = viewport.ViewportSession()
    vs.set_view(viewport.View.of(full.window_matrix, full.view_matrix, 80, 60, window))
    vs.update(bpy.context.evaluated_depsgraph_get())
    image = vs.refine()
    x0, y0, w, h = window
    assert (x0, y0, w, h) == (20, 0, 40, 30)
    inside = np.zeros((60, 80), bool)
    inside[y0:y0 + h, x0:x0 + w] = True
    assert (image.pixels[~inside] == 0).all() and image.pixels[inside][:, 3].max() > 0
    vs.close()


def test_the_thread_renders_the_passes_and_a_new_view_restarts_them(blender, empty_scene):
    import time
    viewport = extension_module("blender.viewport")
    bpy, scene = blender, empty_scene
    _scene(bpy, scene)
    bpy.context.view_layer.update()
    vs = viewport.ViewportSession()
    vs.start()
    try:
        vs.set_view(_f12_view(bpy, scene, 80, 60))
        vs.update(bpy.context.evaluated_depsgraph_get())
        deadline = time.time() + 60
        while not vs.done and time.time() < deadline:
            time.sleep(0.02)
        image = vs.latest()
        assert image.final and image.generation == vs.generation
        vs.set_view(_f12_view(bpy, scene, 40, 30))
        while not vs.done and time.time() < deadline:
            time.sleep(0.02)
        assert vs.latest().pixels.shape == (30, 40, 4) and vs.latest().final
    finally:
        vs.close()


# --------------------------------------------------------------------------------------
# Live A/B: the split buffer, both renders, and what changing A/B costs.

def test_the_split_buffer_shows_a_left_b_right_with_a_divider_and_the_difference_overlay():
    from splat_tracer.render import ab, difference
    h, w = 40, 200
    a = np.zeros((h, w, 4), np.float32)
    a[..., 0], a[..., 3] = 0.5, 1.0            # A: red
    b = np.zeros_like(a)
    b[..., 2], b[..., 3] = 0.5, 1.0            # B: blue
    b[:, :20] = a[:, :20]                      # ... except its first 20 columns, where it is A
    split = 0.3
    out = ab.display_buffer("SPLIT", a.shape, a=a, b=b, split=split)
    cut = ab.divider_column(split, w)
    assert cut == 60
    line = slice(cut - ab.DIVIDER // 2, cut - ab.DIVIDER // 2 + ab.DIVIDER)
    assert (out[:, line] == ab.DIVIDER_RGBA).all()
    np.testing.assert_array_equal(out[:, :line.start], a[:, :line.start])
    np.testing.assert_array_equal(out[:, line.stop:], b[:, line.stop:])
    np.testing.assert_array_equal(ab.display_buffer("A", a.shape, a=a, b=b), a)  # no divider at the edges
    np.testing.assert_array_equal(ab.display_buffer("B", a.shape, a=a, b=b), b)
    np.testing.assert_array_equal(ab.display_buffer("OFF", a.shape, scene=b, a=a), b)
    # B not rendered yet (or of another size): transparent on its side.
    assert (ab.display_buffer("SPLIT", a.shape, a=a, b=None, split=split)[:, line.stop:] == 0).all()

    # The overlay: where A and B differ visibly, the scale's colour (scene-linear, so that the
    # Standard view transform shows the scale's own colours); the legend along the bottom.
    over = ab.display_buffer("SPLIT", a.shape, a=a, b=b, split=split, overlay=True)
    legend = difference.legend(w)
    rows = h - len(legend)
    np.testing.assert_allclose(over[rows:, :, :3], difference.srgb_decode(legend), atol=1e-6)
    de = difference.delta_e(difference.standard_display(a), difference.standard_display(b))
    assert (de[:, :20] == 0).all() and (de[:, 20:] > 50).all()
    part = (slice(0, rows), slice(25, line.start))  # A's side, where A and B differ
    colour = difference.srgb_decode(difference.ramp(de[part]))
    np.testing.assert_allclose(over[part][..., :3], (1 - ab.OVERLAY_OPACITY) * a[part][..., :3]
                               + ab.OVERLAY_OPACITY * colour, atol=1e-6)
    assert (over[part][..., 3] == 1).all()
    np.testing.assert_array_equal(over[:rows, :20], a[:rows, :20])  # no difference: the image itself
    # Exposure brightens what is compared, as the view transform does.
    dim = a * 0.01
    assert (difference.delta_e(difference.standard_display(dim), difference.standard_display(dim * 2)) <
            difference.delta_e(difference.standard_display(dim, exposure=4), difference.standard_display(
                dim * 2, exposure=4))).all()


def test_split_position_from_the_mouse():
    from splat_tracer.render import ab
    assert ab.split_at(100, 100, 400) == 0.0
    assert ab.split_at(300, 100, 400) == 0.5
    assert ab.split_at(900, 100, 400) == 1.0 and ab.split_at(0, 100, 400) == 0.0  # clamped


def test_ab_renders_both_settings_and_changing_only_them_rebuilds_nothing(blender, empty_scene):
    viewport, session_module = extension_module("blender.viewport"), extension_module("blender.session")
    bpy, scene = blender, empty_scene
    _scene(bpy, scene)
    props = scene.splat_tracer.ab
    props.mode = "SPLIT"  # the first time: A becomes General, B the scene's settings (Full)
    assert props.a.method == "GENERAL" and props.b.method == "FULL" and props.initialised
    vs = viewport.ViewportSession()
    with _Recorder(bpy) as rec:
        bpy.context.view_layer.update()
        vs.set_view(_f12_view(bpy, scene, 80, 60))
        vs.update(bpy.context.evaluated_depsgraph_get())
        vs.refine()
        passes = len(viewport.pass_schedule(4))
        assert vs.counters == dict(exports=1, geometry_builds=2, renders=2 * passes, restarts=2)
        images, _ = vs.snapshot()
        assert sorted(images) == ["A", "B"] and images["A"].final and images["B"].final
        # Each is the F12 image of its settings.
        depsgraph = bpy.context.evaluated_depsgraph_get()
        for name, slot in (("A", props.a), ("B", props.b)):
            f12 = session_module.render_frame(depsgraph, slot.core_method()).passes["Combined"]
            _assert_same_to_rounding(images[name].pixels, f12)
        assert not np.array_equal(images["A"].pixels, images["B"].pixels)
        assert viewport.status(images, vs.done) == "Splat Tracer | A: 4 samples, B: 4 samples"

        # Flipping, moving the wipe, the overlay: nothing is rendered again.
        for change in (lambda: setattr(props, "mode", "A"), lambda: setattr(props, "mode", "B"),
                       lambda: setattr(props, "split", 0.8), lambda: setattr(props, "show_difference", True),
                       lambda: bpy.ops.splat_tracer.ab_flip()):
            _, delta = rec.apply(vs, change, scene_setting=True)
            assert delta == dict(exports=0, geometry_builds=0, renders=0, restarts=0)

        # B's switches or epsilon: only B renders again; nothing is exported or built.
        for change in (lambda: setattr(props.b, "epsilon", 0.5), lambda: setattr(props.b, "use_far_phase", False)):
            _, delta = rec.apply(vs, change, scene_setting=True)
            assert delta == dict(exports=0, geometry_builds=0, renders=passes, restarts=1)
        # A's kernel: only A.
        _, delta = rec.apply(vs, lambda: setattr(props.a, "kernel", "SMOOTH"), scene_setting=True)
        assert delta == dict(exports=0, geometry_builds=0, renders=passes, restarts=1)

        # B's radius factor: its clouds are built for it (the mesh is shared), and both
        # factors are exported; both render again (their scenes are new).
        _, delta = rec.apply(vs, lambda: setattr(props.b, "radius_factor", 1.3), scene_setting=True)
        assert delta == dict(exports=2, geometry_builds=1, renders=2 * passes, restarts=2)
        assert sorted(vs.exports) == [1.0, pytest.approx(1.3)]
        # Back to the scene's settings: A and B are dropped; the scene's factor (1) is still built.
        _, delta = rec.apply(vs, lambda: setattr(props, "mode", "OFF"), scene_setting=True)
        assert delta["geometry_builds"] == 0 and delta["renders"] == passes
        assert sorted(vs.snapshot()[0]) == ["SCENE"]
    vs.close()


def test_ab_operators_and_shortcut(blender, empty_scene):
    bpy, scene = blender, empty_scene
    settings = scene.splat_tracer
    props = settings.ab
    assert props.mode == "OFF"
    modes = []
    for _ in range(3):
        assert bpy.ops.splat_tracer.ab_flip() == {"FINISHED"}
        modes.append(props.mode)
    assert modes == ["A", "B", "A"]
    props.mode = "SPLIT"
    bpy.ops.splat_tracer.ab_flip()
    assert props.mode == "A"
    # Copying: the scene's settings into B, and A's into the scene.
    settings.method, settings.epsilon, settings.radius_factor = "NEAREST_CENTRE", 2.0, 0.9
    bpy.ops.splat_tracer.ab_copy(slot="B", direction="FROM_SCENE")
    assert props.b.core_method() == settings.core_method() and props.b.radius_factor == pytest.approx(0.9)
    bpy.ops.splat_tracer.ab_copy(slot="A", direction="TO_SCENE")
    assert settings.method == "GENERAL" and settings.core_method() == props.a.core_method()
    # The shortcut is in the add-on key configuration's 3D View keymap.
    keymap = bpy.context.window_manager.keyconfigs.addon.keymaps["3D View"]
    item = next(k for k in keymap.keymap_items if k.idname == "splat_tracer.ab_flip")
    assert (item.type, item.shift, item.alt, item.ctrl) == ("B", True, True, False)
    assert bpy.types.SPLAT_TRACER_PT_viewport_ab.poll(bpy.context)


# --------------------------------------------------------------------------------------
# Stopping the render thread (issue #22): close() and interpreter exit.

LONG_PASS_CHILD = """
import atexit, sys, threading, time
sys.path[:0] = [{root!r}, {support!r}]
STATE = {{}}
# Registered before viewport's own hook: runs after it (atexit is last in, first out).
atexit.register(lambda: print("at exit: alive", STATE["thread"].is_alive(), flush=True) if STATE else None)
from splat_tracer.blender import viewport
from splat_tracer.render import ab
from splat_tracer.render.camera import Camera
from splat_tracer.render.method import Method
from splat_tracer.render.scene import Instance, RenderScene
from splat_tracer.render.shading import Light, RenderSettings, World
from splat_tracer.render.splats import SplatCloud
from geometry import sphere_cloud

# One pass of 65536 samples: a single 32x32 tile of it takes minutes.
scene = RenderScene([Instance(SplatCloud(*sphere_cloud(20000)))], [Light(type="SUN", power=3.0)],
                    World(colour=(0.1, 0.1, 0.1)))
camera = Camera.look_at((0, 0, 4), (0, 0, 0), (0, 1, 0), 40.0, 1.0)
view = viewport.View(((1.0, 0, 0, 0),) * 4, ((1.0, 0, 0, 0),) * 4, 64, 64, (0, 0, 64, 64))
settings = RenderSettings(samples=65536)
vs = viewport.ViewportSession()
job = viewport._VariantRender(1, "SCENE", scene, camera, view, settings, Method(), 0, ((1, 65536),))
vs._variants = (ab.Variant("SCENE", Method(), 1.0),)
with vs._cond:
    vs._jobs["SCENE"], vs._next["SCENE"] = job, 0
vs.start()
time.sleep(0.5)  # inside the pass
thread = vs._thread
print("passes done", vs.counters["renders"], flush=True)
if {mode!r} == "close":
    t0 = time.monotonic()
    vs.close()
    print("closed in %.2f s, alive %s" % (time.monotonic() - t0, thread.is_alive()), flush=True)
else:
    STATE["thread"] = thread
"""


@pytest.mark.parametrize("mode", ["close", "exit"])
def test_the_render_thread_stops_within_its_timeout_mid_pass(mode):
    """A pass whose one tile takes minutes: close() -- called directly, or by the module's
    atexit hook when Python exits with the session still running -- ends the thread in well
    under close()'s 5 s join, and the process exits cleanly."""
    import subprocess
    import sys
    from pathlib import Path
    root = Path(__file__).resolve().parents[2]
    code = LONG_PASS_CHILD.format(root=str(root), support=str(root / "tests" / "support"), mode=mode)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "passes done 0" in r.stdout, r.stdout  # the close came mid-pass
    if mode == "close":
        line = next(line for line in r.stdout.splitlines() if line.startswith("closed in"))
        assert float(line.split()[2]) < 1.0 and line.endswith("alive False"), line
    else:
        assert "at exit: alive False" in r.stdout, r.stdout


# --------------------------------------------------------------------------------------
# A region collapsed to nothing

class _Engine:
    """SplatTracerEngine's viewport methods on a stand-in (a RenderEngine cannot be made
    outside Blender's draw loop), recording its status lines and redraw requests."""

    def __init__(self, cls):
        self.view_update = cls.view_update.__get__(self)
        self.view_draw = cls.view_draw.__get__(self)
        self._viewport_session = cls._viewport_session.__get__(self)
        self.stats, self.redraws = [], 0

    def update_stats(self, _, text):
        self.stats.append(text)

    def tag_redraw(self):
        self.redraws += 1


def _viewport_context(bpy, scene, width, height):
    """What view_draw reads: the region, and matrices as Blender makes them for its size (a
    0 x 0 region's window matrix is NaN, as calc_matrix_camera gives it; 0 x h is all zeros)."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    cam = scene.camera.evaluated_get(depsgraph)
    window = np.array(cam.calc_matrix_camera(depsgraph, x=width, y=height), np.float64)
    view = np.linalg.inv(np.array(cam.matrix_world.normalized(), np.float64))
    rv3d = SimpleNamespace(window_matrix=window, view_matrix=view, perspective_matrix=window @ view,
                           is_perspective=True, view_perspective="PERSP")
    space = SimpleNamespace(clip_start=cam.data.clip_start, clip_end=cam.data.clip_end, use_render_border=False)
    return SimpleNamespace(region=SimpleNamespace(width=width, height=height), region_data=rv3d, space_data=space)


@pytest.mark.parametrize("empty", [(0, 0), (0, 60), (80, 0)])
def test_a_zero_sized_region_draws_nothing_and_rendering_resumes_when_it_grows(blender, empty_scene, monkeypatch,
                                                                               empty):
    import time
    engine = extension_module("blender.engine")
    bpy, scene = blender, empty_scene
    _scene(bpy, scene)
    bpy.context.view_layer.update()
    drawn = []
    monkeypatch.setattr(engine, "_draw_pixels", lambda _e, _s, pixels, w, h: drawn.append((pixels.shape, w, h)))
    e = _Engine(engine.SplatTracerEngine)
    depsgraph = bpy.context.evaluated_depsgraph_get()

    def draw_until_done(width, height):
        deadline = time.time() + 60
        e.view_draw(_viewport_context(bpy, scene, width, height), depsgraph)
        while not e._splat_viewport.done and time.time() < deadline:
            time.sleep(0.02)
        e.view_draw(_viewport_context(bpy, scene, width, height), depsgraph)

    e.view_update(_viewport_context(bpy, scene, 80, 60), depsgraph)
    vs = e._splat_viewport
    try:
        draw_until_done(80, 60)
        assert drawn[-1] == ((60, 80, 4), 80, 60) and vs.error is None
        before = (len(drawn), len(e.stats), e.redraws, vs.generation, vs.counters["renders"])
        draw_until_done(*empty)  # nothing drawn, rendered, restarted or reported; no exception
        assert (len(drawn), len(e.stats), e.redraws, vs.generation, vs.counters["renders"]) == before
        assert vs.error is None
        draw_until_done(40, 30)  # grown again: the new size renders and is drawn
        assert vs.latest().pixels.shape == (30, 40, 4) and vs.latest().final and vs.error is None
        assert drawn[-1] == ((30, 40, 4), 40, 30) and vs.latest().pixels[..., 3].max() > 0
        assert not any("Splat Tracer:" in s for s in e.stats)
    finally:
        vs.close()


def test_a_view_without_pixels_renders_nothing_without_an_error(blender, empty_scene):
    """The session given a 0-wide view (through the API, not view_draw) renders empty passes
    and needs no camera; a real size afterwards renders."""
    viewport = extension_module("blender.viewport")
    bpy, scene = blender, empty_scene
    _scene(bpy, scene)
    bpy.context.view_layer.update()
    assert viewport.border_window(0, 60) is None and viewport.border_window(80, 0, None, (0, 0, 1, 1)) is None
    full = _f12_view(bpy, scene, 80, 60)
    vs = viewport.ViewportSession()
    vs.set_view(viewport.View.of(full.window_matrix, full.view_matrix, 0, 60))
    vs.update(bpy.context.evaluated_depsgraph_get())
    image = vs.refine()
    assert vs.error is None and image.pixels.shape == (60, 0, 4)
    vs.set_view(full)
    assert vs.refine().pixels[..., 3].max() > 0 and vs.error is None
    vs.close()


def test_camera_view_of_a_panorama_fills_the_frame_as_f12_and_cycles_viewport(blender, empty_scene):
    """The camera view of a panoramic camera renders the panorama (Cycles' viewport does):
    its (u, v) window puts the F12 image's unit square (moved by the shift) on the camera
    frame, whatever the view's zoom and offset; at zoom 1 with no offset the frame is the
    region and the rays are F12's. An unsupported type shows the perspective view."""
    from splat_tracer.blender import export, viewport
    scene = empty_scene
    scene.render.resolution_x, scene.render.resolution_y = RW, RH
    cam, window, view = _view_camera(blender, scene, "PANO", shift=(0.1, -0.05), panorama_type="EQUIRECTANGULAR",
                                     clip_start=0.1, clip_end=100.0)
    depsgraph = blender.context.evaluated_depsgraph_get()
    f12 = export.export_camera(depsgraph, RW, RH, (0, 0, 0))
    space = SimpleNamespace(clip_start=0.1, clip_end=100.0, use_render_border=False)
    for zoom, offset in ((1.0, (0.0, 0.0)), (0.6, (0.1, -0.15))):
        cv_window = _camera_view_window(window, zoom, offset)
        region, rv3d = _stand_ins(cv_window, view, True, "CAMERA")
        v = viewport.view_of(scene, depsgraph, region, rv3d, space)
        (u0, u1, v0, v1), panorama = v.panorama
        assert panorama == f12.panorama
        frame = [tuple(cam.matrix_world @ p) for p in cam.data.view_frame(scene=scene)]
        x0, y0, x1, y1 = viewport.region_rect(rv3d.perspective_matrix, frame, RW, RH)
        at = lambda a, b, t, n: a + (b - a) * t / n  # noqa: E731 - the window's coordinate at region pixel t
        np.testing.assert_allclose([at(u0, u1, x0, RW), at(u0, u1, x1, RW), at(v0, v1, y0, RH), at(v0, v1, y1, RH)],
                                   [0.1, 1.1, -0.05, 0.95], atol=1e-5)
        camera = viewport.camera_from_view(v.window_matrix, v.view_matrix, clip=v.clip, panorama=v.panorama)
        if zoom == 1.0:
            np.testing.assert_allclose(camera.rays(RW, RH)[1], f12.rays(RW, RH)[1], atol=1e-5)
    cam.data.panorama_type = "CENTRAL_CYLINDRICAL"
    assert viewport.view_of(scene, blender.context.evaluated_depsgraph_get(), region, rv3d, space).panorama is None
