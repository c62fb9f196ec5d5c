"""The Mist, Position, Material Index and Environment passes (issue 26, item 3) through
Blender, side by side with Cycles.

One scene for both engines: a scan (a splat-cloud sphere, which Cycles renders as its
points) and a mesh sphere on a floor, under a sun and a blue-grey world, seen at a slant so
that the sky shows above the floor's far edge; 160x120, 16 samples (Cycles: CPU, no
denoising, no adaptive sampling). The World's Mist Pass: start 5, depth 8. Compared where
both engines see the same object (Object Index equal, eroded by 2 pixels: no silhouette).

Tolerances (measured with bpy 5.0.1; each shown below to reject a wrong render):
- MIST_TOL = 0.01, the mean absolute difference of Mist over the covered pixels, for each
  falloff (measured 0.001-0.002); the mist of another falloff is off by 0.05 or more.
- POSITION_TOL = 0.01 of the scene's size (the floor's 8: 0.08), the mean distance between
  the engines' Position over the covered pixels (measured 0.004 of it: Cycles' points are
  spheres, the splats discs); Position in the local frame (without the camera's position
  added back) is off by the camera's distance, 7.
- Material Index: equal on every covered pixel of the meshes (the materials' pass indices);
  the Object Index there differs (a pass index of the object, not of the material, would
  fail). On the scan Cycles writes 0 -- its "Mesh to Points" display carries no material of
  the object -- and the engine the scan's material's index.
- Environment: the world's colour where both see the sky, 0 on every covered pixel -- as
  Cycles (its background pass holds only what camera rays leave into, not the world behind
  objects) -- within 1e-6.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from blender_helpers import add_camera
from test_scene_export import INDEX, cloud_sphere, erode, lamp, plane, principled, render, uv_sphere

W, H = 160, 120
SAMPLES = 16
FLOOR, SCAN, BALL = 1, 2, 3           # object pass indices
FLOOR_MAT, SCAN_MAT, BALL_MAT = 4, 7, 9  # material pass indices
SKY = (0.3, 0.4, 0.6)
SIZE = 8.0  # the floor's side: the scene's size
MIST_START, MIST_DEPTH = 5.0, 8.0
MIST_TOL, POSITION_TOL = 0.01, 0.01
FALLOFF_EXPONENT = {"QUADRATIC": 2.0, "LINEAR": 1.0, "INVERSE_QUADRATIC": 0.5}


def _scene(bpy):
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    mats = []
    for name, index in (("Floor", FLOOR_MAT), ("Scan", SCAN_MAT), ("Ball", BALL_MAT)):
        m = principled(bpy, name)
        m.pass_index = index
        mats.append(m)
    floor = plane(bpy, "Floor", SIZE, (0, 0, 0), mats[0])
    scan = cloud_sphere(bpy, "Scan", 4000, 0.6, (-0.9, 0, 0.6), mats[1])
    ball = uv_sphere(bpy, "Ball", 0.6, (0.9, 0.5, 0.6), mats[2])
    floor.pass_index, scan.pass_index, ball.pass_index = FLOOR, SCAN, BALL
    lamp(bpy, "SUN", rotation=(math.radians(-35), 0, 0), energy=3.0)
    add_camera(bpy, scene, (0, -7, 2.2), (math.radians(78), 0, 0))
    scene.world = bpy.data.worlds.new("Sky")
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (*SKY, 1)
    scene.world.mist_settings.start, scene.world.mist_settings.depth = MIST_START, MIST_DEPTH
    c = scene.cycles
    c.samples, c.device, c.use_denoising, c.use_adaptive_sampling = SAMPLES, "CPU", False, False
    layer = scene.view_layers[0]
    layer.use_pass_object_index = layer.use_pass_material_index = True
    layer.use_pass_mist = layer.use_pass_position = layer.use_pass_environment = True
    return scene


@pytest.fixture(scope="module")
def renders(blender, tmp_path_factory):
    """renders(falloff, engine) -> the view layer's passes, each rendered once per module."""
    folder = tmp_path_factory.mktemp("data_passes")
    scene = _scene(blender)
    cache = {}

    def get(falloff="QUADRATIC", engine="SPLAT_TRACER"):
        if (falloff, engine) not in cache:
            scene.render.engine = engine
            scene.world.mist_settings.falloff = falloff
            cache[falloff, engine] = render(blender, scene, folder / f"{falloff}_{engine}.exr", (W, H))["ViewLayer"]
        return cache[falloff, engine]
    return get


def covered(ours, cycles) -> np.ndarray:
    """The pixels both engines see the same object on, away from its silhouette."""
    same = (ours[INDEX] == cycles[INDEX]) & (cycles[INDEX] > 0)
    return erode(same, 2)


def test_the_passes_carry_cycles_names_and_channels(renders):
    ours, cycles = renders(), renders(engine="CYCLES")
    assert sorted(ours) == sorted(cycles) == ["Combined", "Environment", "Material Index", "Mist", INDEX, "Position"]
    for name in ours:
        assert ours[name].shape == cycles[name].shape, name


def test_material_index_equals_cycles(renders):
    ours, cycles = renders(), renders(engine="CYCLES")
    mask = covered(ours, cycles)
    assert all((cycles[INDEX][mask] == i).sum() > 150 for i in (FLOOR, SCAN, BALL))
    # The scan is Cycles' "Mesh to Points" display, whose points carry no material of the
    # object (Cycles writes 0 there); the engine renders the object's material: its index.
    meshes = mask & (cycles[INDEX] != SCAN)
    np.testing.assert_array_equal(ours["Material Index"][meshes], cycles["Material Index"][meshes])
    assert set(np.unique(cycles["Material Index"][meshes])) == {FLOOR_MAT, BALL_MAT}
    assert (ours["Material Index"][mask & (cycles[INDEX] == SCAN)] == SCAN_MAT).all()
    # The object's pass index in its place (what a pass of the wrong index would hold) fails.
    assert not np.array_equal(ours[INDEX][meshes], cycles["Material Index"][meshes])
    sky = erode((ours[INDEX] == 0) & (cycles[INDEX] == 0), 2)
    assert sky.sum() > 500 and (ours["Material Index"][sky] == 0).all() and (cycles["Material Index"][sky] == 0).all()


def test_position_matches_cycles(renders):
    ours, cycles = renders(), renders(engine="CYCLES")
    mask = covered(ours, cycles)
    distance = np.linalg.norm(ours["Position"][mask] - cycles["Position"][mask], axis=-1)
    print("Position: mean distance / scene size", distance.mean() / SIZE, "99th percentile",
          np.percentile(distance, 99) / SIZE)
    assert distance.mean() < POSITION_TOL * SIZE
    # Without the camera's position added back (the core's local frame) it is far off.
    camera = np.array([0.0, -7.0, 2.2], np.float32)
    local = np.linalg.norm(ours["Position"][mask] - camera - cycles["Position"][mask], axis=-1)
    assert local.mean() > 50 * POSITION_TOL * SIZE
    sky = erode((ours[INDEX] == 0) & (cycles[INDEX] == 0), 2)
    assert (ours["Position"][sky] == 0).all() and (cycles["Position"][sky] == 0).all()


@pytest.mark.parametrize("falloff", sorted(FALLOFF_EXPONENT))
def test_mist_matches_cycles_for_each_falloff(renders, falloff):
    ours, cycles = renders(falloff), renders(falloff, "CYCLES")
    mask = covered(ours, cycles)
    difference = np.abs(ours["Mist"][mask] - cycles["Mist"][mask]).mean()
    print(falloff, "Mist: mean |ours - Cycles|", difference, "range", cycles["Mist"][mask].min(),
          cycles["Mist"][mask].max())
    assert difference < MIST_TOL
    assert cycles["Mist"][mask].min() < 0.1 and cycles["Mist"][mask].max() > 0.5  # the mist's range is in view
    sky = erode((ours[INDEX] == 0) & (cycles[INDEX] == 0), 2)
    assert (ours["Mist"][sky] == 1).all() and np.abs(cycles["Mist"][sky] - 1).max() < 1e-6
    # Our mist under another falloff -- a renderer reading the wrong one -- fails.
    for other in FALLOFF_EXPONENT:
        if other != falloff:
            wrong = ours["Mist"][mask] ** (FALLOFF_EXPONENT[other] / FALLOFF_EXPONENT[falloff])  # m^a -> m^b
            assert np.abs(wrong - cycles["Mist"][mask]).mean() > 5 * MIST_TOL, other


def test_environment_equals_cycles(renders):
    ours, cycles = renders(), renders(engine="CYCLES")
    mask = covered(ours, cycles)
    sky = erode((ours[INDEX] == 0) & (cycles[INDEX] == 0), 2)
    for out in (ours, cycles):
        np.testing.assert_allclose(out["Environment"][sky], np.broadcast_to(SKY, (sky.sum(), 3)), atol=1e-6)
        assert np.abs(out["Environment"][mask]).max() < 1e-6  # black where a surface is met
    assert np.abs(ours["Environment"] - cycles["Environment"]).mean() < 0.01
