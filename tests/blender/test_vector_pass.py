"""The Vector pass with motion blur off (issue 26, item 3) through Blender, side by side with
Cycles.

A mesh cube moving about 1 unit a frame (x -1, 0, 2 and z -0.3, 0, 0.5 at frames 1, 2, 3:
faster after the frame than before it, and up, so that the previous and next motions and
the x and y components all differ) before a camera panning 2 degrees a frame about the
vertical (perspective, and orthographic 7 units wide) and a still wall behind; frame 2 rendered at 64x48, 4 samples (Cycles: CPU, no
denoising). The passes are compared by their means over the cube's and the wall's pixels
(Object Index equal in both, eroded by 2 pixels: no silhouette, where the engine's
pixel-centre sample and Cycles' average over samples differ).

Tolerance (measured with bpy 5.0.1, printed by the test): VECTOR_TOL pixels per component;
a wrong sign or component order is shown to be outside it.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from blender_helpers import add_camera, extension_module
from test_scene_export import INDEX, erode, plane, principled, render

W, H = 64, 48
CUBE, WALL = 1, 2  # object pass indices
VECTOR_TOL = 0.2    # pixels, per component of a region's mean


def _scene(bpy, camera_type):
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.context.preferences.edit.keyframe_new_interpolation_type = "LINEAR"
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    cube = bpy.context.object
    cube.data.materials.append(principled(bpy, "Cube", base=(0.8, 0.3, 0.2)))
    for frame, (x, z) in zip((1, 2, 3), ((-1.0, -0.3), (0.0, 0.0), (2.0, 0.5))):
        cube.location = (x, 0.0, z)
        cube.keyframe_insert("location", frame=frame)
    wall = plane(bpy, "Wall", 8.0, (0, 0, 0), principled(bpy, "Wall", base=(0.5, 0.5, 0.5)))
    wall.location, wall.rotation_euler = (0.0, 6.0, 0.0), (math.radians(90), 0, 0)  # a wall behind
    cube.pass_index, wall.pass_index = CUBE, WALL
    # Orthographic: 7 units wide, the cube 9 pixels across (enough pixels inside its silhouette).
    camera = add_camera(bpy, scene, (0, -8, 0.5), (math.radians(90), 0, 0), type=camera_type, ortho_scale=7.0)
    for frame, angle in zip((1, 2, 3), (-2.0, 0.0, 2.0)):
        camera.rotation_euler = (math.radians(90), 0, math.radians(angle))
        camera.keyframe_insert("rotation_euler", frame=frame)
    scene.frame_set(2)
    scene.splat_tracer.lighting = "HEADLIGHT"
    c = scene.cycles
    c.samples, c.device, c.use_denoising, c.use_adaptive_sampling = 4, "CPU", False, False
    layer = scene.view_layers[0]
    layer.use_pass_object_index = layer.use_pass_vector = True
    return scene


@pytest.fixture(scope="module", params=("PERSP", "ORTHO"))
def renders(blender, tmp_path_factory, request):
    """renders(engine, blur) -> the view layer's passes, each rendered once per camera type."""
    folder = tmp_path_factory.mktemp("vector_pass")
    scene = _scene(blender, request.param)
    cache = {}

    def get(engine="SPLAT_TRACER", blur=False):
        if (engine, blur) not in cache:
            scene.render.engine = engine
            scene.render.use_motion_blur = blur
            cache[engine, blur] = render(blender, scene, folder / f"{engine}{blur:d}.exr", (W, H))["ViewLayer"]
            if engine == "SPLAT_TRACER":
                get.report[blur] = extension_module("blender.session").HISTORY[-1]["report"]
        return cache[engine, blur]
    get.camera_type, get.report = request.param, {}
    return get


def _means(ours, cycles) -> dict:
    same = ours[INDEX] == cycles[INDEX]
    out = {}
    for name, i in (("cube", CUBE), ("wall", WALL)):
        region = erode(same & (cycles[INDEX] == i), 2)
        assert region.sum() > 16, name
        out[name] = (ours["Vector"][region].mean(axis=0), cycles["Vector"][region].mean(axis=0))
    return out


def _ortho_motion(point, before, after) -> np.ndarray:
    """Cycles' (x, y, z, w) of a point's orthographic screen motion: its raster position at
    the previous frame minus at this one, at this one minus at the next; (point, camera pan
    angle in degrees) at each frame."""
    def raster(p, angle):
        a = math.radians(angle)
        d = np.subtract(p, (0, -8, 0.5))  # from the camera
        return np.array([d @ (math.cos(a), math.sin(a), 0), d[2]]) * W / 7.0  # 7 units wide
    now = raster(point, 0.0)
    return np.concatenate([raster(*before) - now, now - raster(*after)])


def test_vector_matches_cycles(renders):
    ours, cycles = renders(), renders("CYCLES")
    if renders.camera_type == "ORTHO":
        # Cycles 5.0.1 projects an orthographic camera's previous and next positions through
        # the perspective lens (measured: its cube's mean is the perspective camera's in x);
        # the engine writes the orthographic motion (said in the report): the cube's front
        # face against its centre's motion, worked out here.
        mine = _means(ours, cycles)["cube"][0]
        expected = _ortho_motion((0, -0.5, 0), ((-1, -0.5, -0.3), -2.0), ((2, -0.5, 0.5), 2.0))
        print(f"orthographic cube: ours {np.round(mine, 3)}, expected {np.round(expected, 3)}")
        assert np.abs(mine - expected).max() < VECTOR_TOL, (mine, expected)
        assert [line for line in renders.report[False] if "Vector" in line] == [
            "ViewLayer: the Vector pass of an orthographic camera is its orthographic screen motion; Cycles' projects "
            "the previous and next frames' positions through the lens as if perspective, so the two differ"]
        return
    assert not [line for line in renders.report[False] if "Vector" in line]  # a rigid scene: nothing to say
    means = _means(ours, cycles)
    for name, (mine, theirs) in means.items():
        print(f"{name}: ours {np.round(mine, 3)}, Cycles {np.round(theirs, 3)}, "
              f"off {np.abs(mine - theirs).max():.4f} px")
        assert np.abs(mine - theirs).max() < VECTOR_TOL, (name, mine, theirs)
    # The cube's motion is large against the tolerance and differs before and after the frame
    # and in x and y: each wrong convention is outside it (the opposite sign, previous and
    # next swapped, x and y swapped).
    mine, theirs = means["cube"]
    for wrong in (-mine, mine[[2, 3, 0, 1]], mine[[1, 0, 3, 2]]):
        assert np.abs(wrong - theirs).max() > 5 * VECTOR_TOL, (wrong, theirs)
    # Where nothing is hit: 0, as Cycles' (away from the wall's edge, where Cycles averages the
    # samples that hit it and Object Index is its pixel-centre sample's miss).
    sky = erode((ours[INDEX] == 0) & (cycles[INDEX] == 0), 2)
    assert sky.sum() > 20 or renders.camera_type == "ORTHO"  # the ortho view is all wall
    assert not ours["Vector"][sky].any() and not cycles["Vector"][sky].any()


def test_vector_with_motion_blur_is_zero_as_cycles(renders):
    ours, cycles = renders(blur=True), renders("CYCLES", blur=True)
    assert not ours["Vector"].any() and not cycles["Vector"].any()
