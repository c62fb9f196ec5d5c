"""The Mist, Position, Material Index and Environment passes of the core (issue 26, item 3),
against their definitions (Cycles' kernel/film): analytic scenes, one sample where the pass
is the pixel-centre sample's. Side by side with Cycles: tests/blender/test_data_passes_cycles.py."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.ndimage import binary_erosion

from splat_tracer.render.camera import Camera
from splat_tracer.render.scene import Instance, RenderScene
from splat_tracer.render.shading import MIST_FALLOFFS, Light, Material, RenderSettings, World

from test_scene import LAMBERT, cloud_sphere, grid_mesh, ortho_down, pixel_points, render

NEW = ("Mist", "Position", "IndexMA", "Env")
SKY = (0.2, 0.3, 0.4)


def mist_of(distance, start, depth, falloff):
    """Cycles' mist for a camera distance (kernel/film/data_passes.h)."""
    m = np.clip((distance - start) / depth, 0.0, 1.0)
    return m ** MIST_FALLOFFS[falloff]


def tilted_floor():
    """A perspective camera over a big floor at z = 0, seeing the sky above its horizon."""
    cam = Camera.look_at((0.0, -6.0, 2.0), (0.0, 4.0, 0.0), fov_y=50.0, aspect=1.5)
    return cam, [Instance(grid_mesh(40.0, 4), materials=(LAMBERT,))]


@pytest.mark.parametrize("falloff", sorted(MIST_FALLOFFS))
def test_mist_is_cycles_mapping_of_the_camera_distance(falloff):
    cam, floor = tilted_floor()
    w, h = 48, 32
    world = World(colour=SKY, mist_start=3.0, mist_depth=20.0, mist_falloff=falloff)
    p = render(floor, world=world, cam=cam, w=w, h=h, passes=("Mist", "Position")).passes
    o, _ = cam.rays(w, h)
    hit = np.any(p["Position"] != 0, axis=-1)
    assert 0.2 < hit.mean() < 0.9  # floor and sky both in view
    distance = np.linalg.norm(p["Position"].astype(np.float64) - o.reshape(h, w, 3)[0, 0], axis=-1)
    expected = mist_of(distance, 3.0, 20.0, falloff)
    # float32 hit points; the square root (Inverse Quadratic) steepens their error near the start.
    np.testing.assert_allclose(p["Mist"][hit], expected[hit], atol=5e-4)
    assert (p["Mist"][~hit] == 1.0).all()  # nothing hit: full mist, as Cycles
    # Another falloff is a different pass: the test can tell them apart.
    other = "LINEAR" if falloff != "LINEAR" else "QUADRATIC"
    assert np.abs(mist_of(distance, 3.0, 20.0, other)[hit] - p["Mist"][hit]).mean() > 0.02


def test_mist_averages_the_samples_and_reads_the_orthographic_distance_along_the_axis():
    # An orthographic camera 10 above a floor at z = 0 under a cloud ball: Cycles' camera
    # distance is along the view axis there (10 on the floor wherever it is seen).
    frame = render([Instance(grid_mesh(10.0, 1, z=0.0), materials=(LAMBERT,))], cam=ortho_down(width=4, height=4),
                   w=16, h=16, world=World(mist_start=2.0, mist_depth=16.0), passes=("Mist",), samples=8)
    np.testing.assert_allclose(frame.passes["Mist"], (10.0 - 2.0) / 16.0, atol=1e-6)


def test_position_is_the_first_hit_of_the_pixel_centre_ray():
    cam = ortho_down(cx=1.0, cy=-0.5, width=4.0, height=4.0)
    floor = grid_mesh(10.0, 1, z=-1.5)
    p = render([Instance(floor, materials=(LAMBERT,))], cam=cam, w=16, h=16, passes=("Position",), samples=4).passes
    xy = pixel_points(cam, 16, 16)
    np.testing.assert_allclose(p["Position"][..., :2], xy, atol=1e-5)
    np.testing.assert_allclose(p["Position"][..., 2], -1.5, atol=1e-6)


def test_material_index_is_each_slots_pass_index_and_0_on_a_miss():
    checker = grid_mesh(1.0, 4, checker=True)
    mats = (Material(pass_index=3), Material(pass_index=7))
    cam = ortho_down(width=3.0, height=3.0)
    p = render([Instance(checker, materials=mats, pass_index=5)], cam=cam, w=48, h=48,
               passes=("IndexMA", "IndexOB")).passes
    xy = pixel_points(cam, 48, 48)
    inside = (np.abs(xy) < 1.0).all(axis=-1)
    cell = np.floor((xy + 1.0) / 0.5).astype(int)
    slot = (cell[..., 0] + cell[..., 1]) % 2
    # Away from the cells' edges (a pixel centre on an edge may take either triangle).
    interior = inside & (np.abs(((xy + 1.0) / 0.5) % 1.0 - 0.5) < 0.4).all(axis=-1)
    assert interior.sum() > 500
    np.testing.assert_array_equal(p["IndexMA"][interior], np.where(slot == 0, 3, 7)[interior])
    assert (p["IndexMA"][~inside] == 0).all() and (p["IndexOB"][interior] == 5).all()


@pytest.mark.parametrize("transparent", [False, True])
def test_environment_is_the_world_camera_rays_leave_into(transparent):
    cam, floor = tilted_floor()
    world = World(colour=SKY, strength=2.0, transparent=transparent)
    p = render(floor, world=world, cam=cam, w=48, h=32, passes=("Env", "Position"), samples=4).passes
    sky = np.all(p["Position"] == 0, axis=-1)
    # The pixels wholly on the floor or the sky (the horizon's are partly both).
    floor_only = np.all(p["Env"] == 0, axis=-1)
    assert floor_only.mean() > 0.3 and sky.mean() > 0.1
    whole_sky = binary_erosion(sky, iterations=2)  # away from the horizon's mixed pixels
    assert whole_sky.sum() > 100
    np.testing.assert_allclose(p["Env"][whole_sky], np.broadcast_to(np.array(SKY) * 2.0, (whole_sky.sum(), 3)),
                               rtol=1e-6)
    assert (p["Env"] <= np.array(SKY) * 2.0 + 1e-6).all()
    hidden = render(floor, world=World(colour=SKY, visibility=frozenset({"diffuse", "glossy", "transmission"}),
                                       transparent=transparent), cam=cam, w=48, h=32, passes=("Env",)).passes
    assert (hidden["Env"] == 0).all()  # hidden from camera rays: none seen


def lit_scene():
    """A cloud ball over a floor under a sun and a grey world, diffuse bounces on: every
    random number of a path is drawn."""
    cloud, floor = cloud_sphere(3000), grid_mesh(10.0, 2, z=-1.5)
    instances = [Instance(cloud, materials=(Material(base_colour=(0.7, 0.5, 0.3), pass_index=2),), pass_index=1),
                 Instance(floor, materials=(dataclasses.replace(LAMBERT, pass_index=4),), pass_index=2)]
    cam = Camera.look_at((0.5, -5.0, 2.0), (0.0, 0.0, -0.5), fov_y=45.0, aspect=1.25)
    return RenderScene(instances, [Light(type="SUN", power=3.0, direction=(0.5, 0.2, -1.0))],
                       World(colour=(0.3, 0.3, 0.3), mist_depth=7.0)), cam


BASE = ("Combined", "Depth", "Normal", "DiffCol", "Emit", "Shadow", "IndexOB", "Splat Count")


@pytest.mark.parametrize("adaptive", [False, True])
def test_the_new_passes_change_nothing_else(adaptive):
    """Asked for or not, the new passes leave every other pass bit-identical: they draw no
    random number and trace no ray."""
    scene, cam = lit_scene()
    rs = RenderSettings(samples=16, diffuse_bounces=2, adaptive=adaptive)
    off = scene.render(cam, 40, 32, rs, passes=BASE)
    on = scene.render(cam, 40, 32, rs, passes=BASE + NEW)
    for name in BASE:
        np.testing.assert_array_equal(on.passes[name], off.passes[name], err_msg=name)
    assert on.counters == off.counters
    mist, env = on.passes["Mist"], on.passes["Env"]
    assert 0.0 <= mist.min() and mist.max() == 1.0 and (mist < 1).mean() > 0.5
    assert (env[on.passes["Depth"] < 1e9] <= 0.3 + 1e-6).all()
    np.testing.assert_array_equal(on.passes["IndexMA"] > 0, on.passes["Depth"] < 1e9)
