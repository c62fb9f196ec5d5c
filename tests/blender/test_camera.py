"""The camera from Blender's parameters in double (issue 22): clipping ranges of 1e8 and
more (0.001 to 1e5 m, ordinary for a landscape scan) render as an ordinary range does, in
F12 and in the viewport, beside Cycles; for ordinary ranges the rays are the ones the
float32 projection matrix gave, and the comparison used catches a wrong camera."""
from __future__ import annotations

import itertools
import math
from types import SimpleNamespace

import numpy as np
import pytest

from blender_helpers import add_camera, extension_module
from test_scene_export import black_world, cloud_sphere, lamp, plane, principled, render

W, H = 64, 48
ORDINARY, HUGE = (0.1, 100.0), [(0.001, 1e5), (0.01, 1e6)]
# Depth of a visible pixel at a huge clip range against the ordinary one: the rays start on
# another near plane, so the same hit is found from another float32 origin (measured: at
# most 5e-7 relative; a camera shifted by one pixel changes the coverage, see the last tests).
DEPTH_RTOL = 1e-5


def _scene(bpy, scene, kind="PERSP", shift=(0.0, 0.0)):
    """A floor and a closed cloud on it, lit by a sun, in a black world."""
    grey = principled(bpy, "Grey")
    plane(bpy, "Floor", 8.0, (0, 0, 0), grey)
    cloud_sphere(bpy, "Ball", 3000, 0.8, (0.3, 0.4, 0.8), grey)
    lamp(bpy, "SUN", rotation=(math.radians(30), 0, math.radians(20)), energy=3.0)
    black_world(bpy, scene)
    add_camera(bpy, scene, (0.5, -6.0, 3.5), (math.radians(60), 0, math.radians(4)), type=kind, lens=35,
               ortho_scale=7.0, shift_x=shift[0], shift_y=shift[1])
    scene.render.resolution_x, scene.render.resolution_y = W, H
    scene.cycles.samples = scene.cycles.preview_samples = 1
    scene.render.film_transparent = True  # alpha: what the camera sees
    scene.view_layers[0].use_pass_z = True
    return scene.camera


def _ours(bpy, scene, tmp_path, clip, name):
    scene.camera.data.clip_start, scene.camera.data.clip_end = clip
    scene.render.engine = "SPLAT_TRACER"
    return render(bpy, scene, tmp_path / f"{name}.exr", (W, H))["ViewLayer"]


def _coverage(depth):
    return depth < 1e9  # the background's depth is 1e10 (Blender's, and ours)


def _mismatch(reference: dict, other: dict):
    """None when `other` shows what `reference` shows: the same coverage, the depth of
    every visible pixel within DEPTH_RTOL; else what differs."""
    a, b = reference["Depth"], other["Depth"]
    if not _coverage(b).any():
        return "empty frame"
    if not np.array_equal(_coverage(a), _coverage(b)):
        return f"coverage differs at {int((_coverage(a) != _coverage(b)).sum())} pixels"
    seen = _coverage(a)
    rel = np.abs(a[seen] - b[seen]) / a[seen]
    return None if rel.max() <= DEPTH_RTOL else f"depth differs by up to {rel.max():.3g} (relative)"


@pytest.mark.parametrize("kind, shift", [("PERSP", (0.0, 0.0)), ("PERSP", (0.12, -0.08)), ("ORTHO", (0.0, 0.0)),
                                         ("ORTHO", (-0.1, 0.05))])
def test_huge_clip_ranges_render_what_an_ordinary_one_does(blender, empty_scene, tmp_path, kind, shift):
    _scene(blender, empty_scene, kind, shift)
    reference = _ours(blender, empty_scene, tmp_path, ORDINARY, "ordinary")
    assert _coverage(reference["Depth"]).mean() > 0.5  # the floor and the ball fill the frame
    for clip in HUGE:
        huge = _ours(blender, empty_scene, tmp_path, clip, f"huge_{clip[1]:g}")
        assert _mismatch(reference, huge) is None, (clip, _mismatch(reference, huge))
        assert np.isfinite(huge["Combined"]).all() and huge["Combined"][..., :3].max() > 0


def test_cycles_and_ours_see_the_same_at_a_huge_clip_range(blender, empty_scene, tmp_path):
    """Cycles renders the huge range (the issue's reference); both see the floor and the
    ball at the same depths. Cycles draws the cloud's points as spheres and jitters its
    one sample in the pixel, so only the pixels inside both coverages compare (measured:
    IoU 0.995, median relative depth difference 1.2e-5, 90th percentile 2e-5)."""
    scene = empty_scene
    _scene(blender, scene, "PERSP", (0.05, 0.0))
    ours = _ours(blender, scene, tmp_path, HUGE[0], "ours")
    scene.render.engine = "CYCLES"
    scene.cycles.device, scene.cycles.samples = "CPU", 1
    cycles = render(blender, scene, tmp_path / "cycles.exr", (W, H))["ViewLayer"]
    a, b = _coverage(ours["Depth"]), _coverage(cycles["Depth"])
    assert (a & b).sum() / (a | b).sum() > 0.98
    both = a & b
    rel = np.abs(ours["Depth"][both] - cycles["Depth"][both]) / cycles["Depth"][both]
    assert np.median(rel) < 1e-3 and np.quantile(rel, 0.9) < 1e-2


def _matrix_rays(projection, world_from_camera, width, height):
    """The rays the float32 projection matrix gave (before issue 22): pixel centres
    unprojected on the near and far planes through its inverse, in double."""
    m = np.array(world_from_camera, np.float64) @ np.linalg.inv(np.array(projection, np.float64))
    j, i = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    ndc = np.stack([2 * j / width - 1, 1 - 2 * i / height], axis=-1).reshape(-1, 2)

    def unproject(z):
        p = np.column_stack([ndc, np.full(len(ndc), z), np.ones(len(ndc))]) @ m.T
        return p[:, :3] / p[:, 3:]
    a, b = unproject(-1.0), unproject(1.0)
    return a, (b - a) / np.linalg.norm(b - a, axis=1, keepdims=True)


# Directions: the float32 matrix's entries carry 6e-8 relative error, and the rays are
# stored in float32: measured at most 1.4e-7 apart. One pixel at these fields of view is
# 1e-3 to 1e-2 radians; a shift by one pixel, a swapped sensor fit or an ignored pixel
# aspect moves the rays by 0.016, 0.067 and 0.078.
RAY_ATOL = 2e-6


def _ray_mismatch(camera, projection, world_from_camera, width, height) -> float:
    o, d = camera.rays(width, height)
    mo, md = _matrix_rays(projection, world_from_camera, width, height)
    offset = o.astype(np.float64) - mo
    off_line = offset - np.einsum("ij,ij->i", offset, md)[:, None] * md
    return max(float(np.abs(d - md).max()), float(np.abs(off_line).max()) / max(1.0, float(np.abs(mo).max())))


CASES = list(itertools.product(("PERSP", "ORTHO"), ("AUTO", "HORIZONTAL", "VERTICAL"),
                               ((64, 48), (48, 64), (50, 50)), ((1.0, 1.0), (2.0, 1.0), (1.0, 1.5)),
                               ((0.0, 0.0), (0.2, -0.13))))


def test_rays_from_parameters_are_the_matrix_rays_for_ordinary_clip_ranges(blender, empty_scene):
    export = extension_module("blender.export")
    scene = empty_scene
    cam = add_camera(blender, scene, (1.0, -5.0, 2.0), (1.2, 0.1, 0.3), sensor_width=32.0, sensor_height=21.0,
                     lens=35.0, ortho_scale=7.0, clip_start=0.1, clip_end=100.0)
    worst = 0.0
    for kind, fit, (w, h), (ax, ay), shift in CASES:
        d = cam.data
        d.type, d.sensor_fit, (d.shift_x, d.shift_y) = kind, fit, shift
        scene.render.pixel_aspect_x, scene.render.pixel_aspect_y = ax, ay
        depsgraph = blender.context.evaluated_depsgraph_get()
        projection = cam.calc_matrix_camera(depsgraph, x=w, y=h, scale_x=ax, scale_y=ay)
        ours = export.export_camera(depsgraph, w, h, (0.0, 0.0, 0.0))
        error = _ray_mismatch(ours, projection, cam.matrix_world.normalized(), w, h)
        assert error < RAY_ATOL, (kind, fit, w, h, ax, ay, shift, error)
        worst = max(worst, error)
    assert worst > 0  # the comparison compares something


@pytest.mark.parametrize("wrong", ["shift one pixel", "sensor fit swapped", "pixel aspect ignored"])
def test_the_ray_tolerance_catches_a_wrong_camera(blender, empty_scene, wrong):
    from splat_tracer.render.camera import Camera
    export = extension_module("blender.export")
    scene = empty_scene
    cam = add_camera(blender, scene, (1.0, -5.0, 2.0), (1.2, 0.1, 0.3), lens=35.0, shift_x=0.1)
    w, h, ax = 64, 48, 1.0
    if wrong == "pixel aspect ignored":
        ax = scene.render.pixel_aspect_x = 1.3
    depsgraph = blender.context.evaluated_depsgraph_get()
    projection = cam.calc_matrix_camera(depsgraph, x=w, y=h, scale_x=ax, scale_y=1.0)
    data = SimpleNamespace(**{k: getattr(cam.data, k) for k in ("type", "lens", "ortho_scale", "sensor_width",
                                                                  "sensor_height", "sensor_fit", "shift_x",
                                                                  "shift_y")})
    if wrong == "shift one pixel":
        data.shift_x += 1.0 / w  # the horizontal fit: a shift of 1 is the image's width
    elif wrong == "sensor fit swapped":
        data.sensor_fit = "VERTICAL"
    frustum = extension_module("blender.export.scene").camera_frustum(data, w, h, 1.0 if wrong == "pixel aspect ignored" else ax, 1.0)
    bad = Camera.from_frustum(np.array(cam.matrix_world.normalized()), frustum, (0.1, 100.0))
    assert _ray_mismatch(bad, projection, cam.matrix_world.normalized(), w, h) > 100 * RAY_ATOL


@pytest.mark.parametrize("wrong", ["shift one pixel", "sensor fit swapped"])
def test_the_render_comparison_catches_a_wrong_camera(blender, empty_scene, tmp_path, wrong):
    cam = _scene(blender, empty_scene, "PERSP")
    reference = _ours(blender, empty_scene, tmp_path, ORDINARY, "reference")
    if wrong == "shift one pixel":
        cam.data.shift_x = 1.0 / W
    else:
        cam.data.sensor_fit = "VERTICAL"
    assert _mismatch(reference, _ours(blender, empty_scene, tmp_path, HUGE[0], "wrong")) is not None


def test_a_camera_scaled_to_zero_is_named_with_the_cause(blender, empty_scene):
    export = extension_module("blender.export")
    cam = add_camera(blender, empty_scene, (0, -5, 0), (math.radians(90), 0, 0))
    cam.name = "Survey Cam"
    for scale in ((0, 0, 0), (1, 1, 0), (0, 1, 1)):
        cam.scale = scale
        depsgraph = blender.context.evaluated_depsgraph_get()
        with pytest.raises(RuntimeError, match=r"camera 'Survey Cam' is scaled to zero"):
            export.export_camera(depsgraph, W, H, (0, 0, 0))
    cam.scale = (1, 1, 1)
    cam.data.clip_start, cam.data.clip_end = 5.0, 2.0  # unchanged: refused as before
    with pytest.raises(RuntimeError, match="Clip Start"):
        export.export_camera(blender.context.evaluated_depsgraph_get(), W, H, (0, 0, 0))


# --------------------------------------------------------------------------------------
# The viewport. Headless Blender computes no RegionView3D matrices (see test_viewport.py):
# the stand-ins carry a camera's float32 projection at the huge range as the window
# matrix, as Blender's view would.

def _view(bpy, scene, perspective_kind, clip):
    viewport = extension_module("blender.viewport")
    depsgraph = bpy.context.evaluated_depsgraph_get()
    cam = scene.camera
    window = cam.calc_matrix_camera(depsgraph, x=W, y=H)
    view = cam.matrix_world.inverted()
    region = SimpleNamespace(width=W, height=H)
    rv3d = SimpleNamespace(window_matrix=window, view_matrix=view, perspective_matrix=window @ view,
                           is_perspective=True, view_perspective=perspective_kind)
    space = SimpleNamespace(clip_start=clip[0], clip_end=clip[1], use_render_border=False)
    return viewport.view_of(scene, depsgraph, region, rv3d, space)


@pytest.mark.parametrize("kind", ["CAMERA", "PERSP"])
def test_the_viewport_renders_a_huge_clip_range(blender, empty_scene, tmp_path, kind):
    """In the camera view (the camera's range) and in a free perspective view (the View3D's
    range, here given the camera's lens so that the images compare), at 0.001 to 1e5."""
    viewport = extension_module("blender.viewport")
    bpy, scene = blender, empty_scene
    cam = _scene(bpy, scene)
    f12 = _ours(bpy, scene, tmp_path, ORDINARY, "f12")["Combined"]
    cam.data.clip_start, cam.data.clip_end = HUGE[0]
    bpy.context.view_layer.update()
    view = _view(bpy, scene, kind, HUGE[0])
    assert view.clip == pytest.approx(HUGE[0], rel=1e-7)
    # The window matrix alone has lost the range (float32): read from it, the far plane
    # is at infinity; the view's own range is used instead.
    with pytest.raises(ValueError, match="clipping range"):
        viewport.camera_from_view(view.window_matrix, view.view_matrix)
    vs = viewport.ViewportSession()
    try:
        vs.set_view(view)
        vs.update(bpy.context.evaluated_depsgraph_get())
        image = vs.refine()
        assert image.final and image.pixels[..., :3].max() > 0
        seen = image.pixels[..., 3] > 0
        assert seen.mean() > 0.5 and np.array_equal(seen, f12[..., 3] > 0)
    finally:
        vs.close()
