"""Depth of field (issue 25, item 1) through Blender, side by side with Cycles.

Both engines render the same scene: an emitting half-plane (a mesh, so that Cycles sees
what we see) in a black world, seen square-on by a camera whose Depth of Field settings
(camera.data.dof) are set as an artist sets them for Cycles. The blur of the plane's edge
is measured the same way in both renders: the rows' mean profile across the edge,
normalised between its dark and lit plateaus, and its 10-90 % width in pixels (linear
interpolation between pixel centres).

Tolerance: WIDTH_RTOL = 15 % between the two engines' widths. Measured (bpy 5.0.1): f/1
5.52 px here, 5.47 in Cycles; f/0.5 10.63 and 10.71; orthographic f/16 4.35 and 4.30 --
within 1 %. A wrong f-stop conversion by 2x (the aperture's diameter taken for its
radius, or the f-stop doubled) changes the width by 1.96x at these blur sizes, far
outside. In focus, the edge is the pixel filter's alone: 1.42 px with or without the lens
here (Cycles: 1.28 px; its filter's own width, the same without depth of field).
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from blender_helpers import add_camera, extension_module
from test_scene_export import black_world, mesh_object, principled, render

W, H = 128, 48
SAMPLES = 32
WIDTH_RTOL = 0.15
FOCAL_LENGTH = 50.0  # mm, on the default 36 mm sensor: 0.72 / W per pixel on the unit plane


def _half_plane(bpy, depth: float):
    """An emitting half-plane x > 0 at distance `depth` in front of a camera at the origin
    looking down -Z (the plane reaches far beyond the view)."""
    import bmesh

    big = 50.0 * depth

    def build(bm):
        vs = [bm.verts.new(v) for v in ((0, -big, -depth), (big, -big, -depth), (big, big, -depth),
                                        (0, big, -depth))]
        bm.faces.new(vs)
    glow = principled(bpy, "Glow", base=(0, 0, 0), specular=0.0, emission=(1, 1, 1, 1.0))
    return mesh_object(bpy, "HalfPlane", build, materials=[glow])


def _setup(bpy, scene, depth: float, fstop=None, focus=2.0, kind="PERSP", **camera):
    _half_plane(bpy, depth)
    black_world(bpy, scene)
    cam = add_camera(bpy, scene, (0, 0, 0), (0, 0, 0), type=kind, lens=FOCAL_LENGTH, clip_start=0.1,
                     clip_end=1000.0, **camera)
    dof = cam.data.dof
    dof.use_dof = fstop is not None
    dof.aperture_fstop = fstop or 2.8
    dof.focus_distance = focus
    scene.cycles.samples, scene.cycles.device = SAMPLES, "CPU"
    scene.cycles.use_denoising = False
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.max_bounces = 0
    return cam


def _render(bpy, scene, tmp_path, engine: str, name: str) -> np.ndarray:
    scene.render.engine = engine
    return render(bpy, scene, tmp_path / f"{name}_{engine}.exr", (W, H))["ViewLayer"]["Combined"][..., 0]


def edge_width(image: np.ndarray) -> float:
    """The 10-90 % width (pixels) of the edge across the columns of `image`."""
    profile = image.mean(axis=0)
    dark, lit = np.median(profile[: W // 8]), np.median(profile[-W // 8:])
    p = (profile - dark) / (lit - dark)
    x = np.arange(W) + 0.5

    def crossing(level):
        k = int(np.argmax(p >= level))  # the first column at or above the level
        return x[k - 1] + (level - p[k - 1]) / (p[k] - p[k - 1]) if k > 0 else x[0]
    return float(crossing(0.9) - crossing(0.1))


def _both(bpy, scene, tmp_path, name):
    return {e: edge_width(_render(bpy, scene, tmp_path, e, name)) for e in ("SPLAT_TRACER", "CYCLES")}


DEPTH, FOCUS = 8.0, 1.0  # the plane far behind the plane in focus: blur = aperture x (1/f - 1/z)


def test_blur_width_matches_cycles_at_two_fstops(blender, empty_scene, tmp_path):
    """f/1 and f/0.5 at 50 mm: aperture radii 25 and 50 mm, blur radii 3.9 and 7.8 pixels
    (10-90 % widths about 6 and 11 pixels with the pixel filter)."""
    cam = _setup(blender, empty_scene, DEPTH, fstop=1.0, focus=FOCUS)
    widths = {1.0: _both(blender, empty_scene, tmp_path, "f1")}
    cam.data.dof.aperture_fstop = 0.5
    widths[0.5] = _both(blender, empty_scene, tmp_path, "f05")
    print("10-90 % widths (px) by f-stop:", widths)
    for fstop, w in widths.items():
        assert w["SPLAT_TRACER"] == pytest.approx(w["CYCLES"], rel=WIDTH_RTOL), fstop
    assert widths[0.5]["CYCLES"] > 1.6 * widths[1.0]["CYCLES"]  # the blur is the lens's, not the filter's
    # A conversion wrong by 2x (the diameter taken for the radius: f/1 rendered as f/0.5,
    # or f/0.5 as f/1) would miss the tolerance: the width at the other f-stop lies outside.
    assert abs(widths[1.0]["CYCLES"] / widths[0.5]["CYCLES"] - 1) > 2 * WIDTH_RTOL
    assert abs(widths[0.5]["CYCLES"] / widths[1.0]["CYCLES"] - 1) > 2 * WIDTH_RTOL


def test_the_plane_in_focus_is_as_sharp_as_without_depth_of_field(blender, empty_scene, tmp_path):
    cam = _setup(blender, empty_scene, 2.0, fstop=None)
    sharp = edge_width(_render(blender, empty_scene, tmp_path, "SPLAT_TRACER", "pinhole"))
    cam.data.dof.use_dof, cam.data.dof.aperture_fstop, cam.data.dof.focus_distance = True, 0.5, 2.0
    focused = _both(blender, empty_scene, tmp_path, "focused")
    print("in focus (px): pinhole", sharp, "with f/0.5", focused)
    assert sharp < 2.0  # the pixel filter's own width
    assert focused["SPLAT_TRACER"] == pytest.approx(sharp, abs=0.1)
    assert focused["CYCLES"] == pytest.approx(sharp, abs=0.3)


def test_focus_object_focuses_at_its_distance_along_the_view_axis(blender, empty_scene, tmp_path):
    """An Empty off the axis at 8 m depth (9.2 m away): the plane at 8 m is sharp, the
    Focus Distance (1 m) is not used; Cycles agrees."""
    cam = _setup(blender, empty_scene, DEPTH, fstop=0.5, focus=FOCUS)
    target = blender.data.objects.new("Target", None)
    empty_scene.collection.objects.link(target)
    target.location = (4.0, 2.0, -DEPTH)
    cam.data.dof.focus_object = target
    depsgraph = blender.context.evaluated_depsgraph_get()
    export = extension_module("blender.export.scene")
    assert export.focus_distance(cam.evaluated_get(depsgraph), depsgraph) == pytest.approx(DEPTH, rel=1e-6)
    widths = _both(blender, empty_scene, tmp_path, "focus_object")
    print("focus object (px):", widths)
    assert widths["SPLAT_TRACER"] < 2.0 and widths["SPLAT_TRACER"] == pytest.approx(widths["CYCLES"], abs=0.3)


def test_focus_bone_is_the_bones_head(blender, empty_scene):
    """Focus on Bone: the distance to the posed bone's head (Cycles multiplies the
    object's matrix by the pose bone's)."""
    bpy = blender
    cam = add_camera(bpy, empty_scene, (0, 0, 0), (0, 0, 0))
    arm = bpy.data.objects.new("Rig", bpy.data.armatures.new("Rig"))
    empty_scene.collection.objects.link(arm)
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode="EDIT")
    bone = arm.data.edit_bones.new("Aim")
    bone.head, bone.tail = (0.0, 0.0, -3.0), (0.0, 1.0, -3.0)
    bpy.ops.object.mode_set(mode="OBJECT")
    arm.location = (0.5, 0.0, -1.0)
    arm.pose.bones["Aim"].location = (0.0, 0.0, 0.0)
    cam.data.dof.use_dof, cam.data.dof.focus_object, cam.data.dof.focus_subtarget = True, arm, "Aim"
    depsgraph = bpy.context.evaluated_depsgraph_get()
    export = extension_module("blender.export.scene")
    assert export.focus_distance(cam.evaluated_get(depsgraph), depsgraph) == pytest.approx(4.0, rel=1e-6)
    cam.data.dof.focus_subtarget = ""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    assert export.focus_distance(cam.evaluated_get(depsgraph), depsgraph) == pytest.approx(1.0, rel=1e-6)


def test_orthographic_blur_matches_cycles(blender, empty_scene, tmp_path):
    """Cycles' orthographic lens: radius 1 / (2 f-stop) scene units, focus measured from the
    camera (not the near plane: clip start 1 m here would double the blur under that rule).
    f/16 -> 31 mm; at 8 m with focus 2 m the blur radius is 3x that, 94 mm = 3 pixels of a
    4 m wide view."""
    cam = _setup(blender, empty_scene, DEPTH, fstop=16.0, focus=2.0, kind="ORTHO", ortho_scale=4.0)
    cam.data.clip_start = 1.0
    widths = _both(blender, empty_scene, tmp_path, "ortho")
    print("orthographic (px):", widths)
    assert widths["SPLAT_TRACER"] == pytest.approx(widths["CYCLES"], rel=WIDTH_RTOL)
    assert widths["CYCLES"] > 3.0  # blurred beyond the filter's width


def test_depth_of_field_off_is_the_pinhole(blender, empty_scene):
    cam = _setup(blender, empty_scene, DEPTH, fstop=None)
    export = extension_module("blender.export.scene")
    depsgraph = blender.context.evaluated_depsgraph_get()
    assert export.export_camera(depsgraph, W, H, (0, 0, 0)).lens is None
    cam.data.dof.use_dof = True
    cam.data.dof.aperture_blades, cam.data.dof.aperture_rotation, cam.data.dof.aperture_ratio = 6, 0.3, 1.5
    depsgraph = blender.context.evaluated_depsgraph_get()
    lens = export.export_camera(depsgraph, W, H, (0, 0, 0)).lens
    assert (lens.blades, lens.ratio) == (6, pytest.approx(1.5)) and lens.rotation == pytest.approx(0.3)
    assert lens.radius == pytest.approx(FOCAL_LENGTH * 1e-3 / (2 * 2.8)) and lens.focus_distance == 2.0


def test_the_camera_depth_of_field_panels_show_for_the_engine(blender, empty_scene):
    for name in ("DATA_PT_camera_dof", "DATA_PT_camera_dof_aperture"):
        panel = getattr(blender.types, name)
        assert "SPLAT_TRACER" in panel.COMPAT_ENGINES
        assert panel.poll(SimpleNamespace(camera=blender.data.cameras.new("C"), engine="SPLAT_TRACER"))


def test_the_viewport_renders_depth_of_field_in_the_camera_view_only(blender, empty_scene):
    """As Cycles' viewport: the scene camera's lens through the camera view, a pinhole in
    any other view; a change of the lens is a change of the View (rendered again)."""
    viewport = extension_module("blender.viewport")
    cam = _setup(blender, empty_scene, DEPTH, fstop=1.0, focus=FOCUS)
    depsgraph = blender.context.evaluated_depsgraph_get()
    lens = viewport.view_lens(empty_scene, depsgraph, SimpleNamespace(view_perspective="CAMERA"))
    assert lens is not None and lens.radius == pytest.approx(0.025) and lens.focus_distance == FOCUS
    assert viewport.view_lens(empty_scene, depsgraph, SimpleNamespace(view_perspective="PERSP")) is None
    eye = np.eye(4)
    a = viewport.View.of(eye, eye, 64, 48, lens=lens)
    cam.data.dof.aperture_fstop = 2.0
    depsgraph = blender.context.evaluated_depsgraph_get()
    other = viewport.view_lens(empty_scene, depsgraph, SimpleNamespace(view_perspective="CAMERA"))
    assert a != viewport.View.of(eye, eye, 64, 48, lens=other)
    window = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, -1.0, -0.2], [0, 0, -1.0, 0]])
    assert viewport.camera_from_view(window, eye, clip=(0.1, 100.0), lens=lens).lens == lens
    assert viewport.camera_from_view(window, eye, clip=(0.1, 100.0)).lens is None
