"""Open clouds are two-sided all the way through shading (issue 27, item 2): a scan whose
normals face away from where it is seen from -- a depth frame oriented away from its sensor --
renders as the same scan oriented towards it, under the headlight and under lamps, with
mirror and glass materials; closed clouds keep their one-sided rules. Plain core, no Blender.

The stand-in is a quantised, noisy depth frame (frames.ball_corner_frame) imported as a file
without normals would be (prepare.prepare: PCA normals, k-NN radii), then oriented all away
from the sensor or all towards it.
"""
from __future__ import annotations

import numpy as np
import pytest

from splat_tracer.pointcloud import prepare
from splat_tracer.pointcloud.cloud import make_cloud
from splat_tracer.render.camera import Camera
from splat_tracer.render.method import PRESETS, Method
from splat_tracer.render.scene import Instance, Mesh, RenderScene
from splat_tracer.render.shading import Light, Material, RenderSettings, World
from splat_tracer.render.splats import SplatCloud

from frames import ball_corner_frame
from geometry import sphere_cloud

W, H = 160, 120
FULL = Method.preset("FULL")
# A pixel is near-black below this share of the frame's median brightness facing the sensor.
NEAR_BLACK = 0.05
# Issue 27's bound on the near-black share of covered pixels.
MAX_NEAR_BLACK = 0.02


@pytest.fixture(scope="module")
def frame():
    """(local positions, normals facing away from the sensor, radii, camera at the sensor)."""
    points, _ = ball_corner_frame()
    prepared = prepare.prepare(make_cloud("depth frame", points.copy(), format="TEXT"), "depth frame")
    n = prepared.cloud.normals.astype(np.float64)
    seen_from = prepared.local + prepared.origin  # the sensor is the file's origin
    away = np.where((np.einsum("ij,ij->i", n, seen_from) > 0)[:, None], n, -n)
    assert not prepared.hood.closed_guess  # the importer calls it open: the rule applies
    eye = -prepared.origin
    camera = Camera.look_at(eye, eye + (0.0, 0.0, 1.0), up=(0.0, -1.0, 0.0), fov_y=50.0, aspect=W / H)
    return prepared.local, away, prepared.radii, camera


def view_directions(camera):
    _, d = camera.rays(W, H)
    return (d / np.linalg.norm(d, axis=1, keepdims=True)).reshape(H, W, 3)


def luminance(rgb):
    return rgb[..., :3] @ np.array([0.2126, 0.7152, 0.0722])


@pytest.mark.parametrize("preset", PRESETS)
def test_the_headlight_shows_the_back_as_the_front(frame, preset):
    """SplatCloud.render: the frame oriented away renders as the frame oriented towards the
    sensor -- colour and depth within 1e-6 (measured: equal), normals turned towards the
    camera as Cycles writes a back face's (before: every normal faced away)."""
    local, away, radii, camera = frame
    method = Method.preset(preset)
    back = SplatCloud(local, away, radii).render(camera, W, H, method=method)
    front = SplatCloud(local, -away, radii).render(camera, W, H, method=method)
    covered = front.depth < 1e9
    assert covered.mean() > 0.8
    np.testing.assert_allclose(back.rgba, front.rgba, atol=1e-6)
    np.testing.assert_allclose(back.depth, front.depth, rtol=1e-6)
    np.testing.assert_allclose(back.normal, front.normal, atol=1e-6)
    faces = np.einsum("hwc,hwc->hw", back.normal, view_directions(camera)) < 0
    assert faces[covered].mean() > 0.99
    lum = luminance(back.rgba)
    assert (lum[covered] < NEAR_BLACK * np.median(lum[covered])).mean() <= MAX_NEAR_BLACK


MATERIALS = {
    "diffuse": Material(base_colour=(0.8, 0.8, 0.8), specular_level=0.0, roughness=1.0),
    "plastic": Material(base_colour=(0.6, 0.5, 0.4), roughness=0.4),
    "mirror": Material(base_colour=(0.9, 0.9, 0.9), metallic=1.0, roughness=0.0),
    "glass": Material(transmission=1.0, roughness=0.0, ior=1.45),
}


def lit_render(cloud, camera, material, eye, method=FULL):
    """The cloud under a sun and a point lamp on the sensor's side, in a blue-grey world,
    with a floor mesh on the sensor's side for mirror and glass to show."""
    floor = Mesh(np.array([[-5, 1.0, -1], [5, 1.0, -1], [5, 1.0, 6], [-5, 1.0, 6]], float) + eye,
                 np.array([[0, 1, 2], [0, 2, 3]]))
    scene = RenderScene([Instance(cloud, materials=(material,)),
                         Instance(floor, materials=(Material(base_colour=(0.7, 0.3, 0.2)),))],
                        lights=[Light("SUN", power=3.0, direction=(0.3, 0.4, 1.0)),
                                Light("POINT", power=100.0, position=tuple(eye + (0.5, -0.5, 0.2)))],
                        world=World(colour=(0.3, 0.35, 0.4)))
    return scene.render(camera, W, H, RenderSettings(samples=1), method=method, passes=("Depth", "Normal", "IndexOB"))


@pytest.mark.parametrize("name", sorted(MATERIALS))
def test_lamps_light_the_back_as_the_front(frame, name):
    """The scene integrator, one sample: oriented away, the frame is lit as oriented towards
    the sensor -- mean brightness within 1 % (glass excepted), at most 2 % of the covered
    pixels near-black (below 5 % of the median) and the Normal pass equal within 1e-5.
    Measured: mean 0.2-0.3 % off, near-black 0-0.2 %. Before (the sheet's shadow rays took
    the neighbouring discs, met from their front, for occluders): diffuse 16.4 % near-black,
    39 % darker. Glass is not symmetric, in Cycles either: a back face is where a ray leaves
    the glass (IOR inverted), so it refracts otherwise (measured: 4.8 % brighter)."""
    local, away, radii, camera = frame
    eye = np.asarray(camera.local_from_camera)[:3, 3]
    back = lit_render(SplatCloud(local, away, radii), camera, MATERIALS[name], eye)
    front = lit_render(SplatCloud(local, -away, radii), camera, MATERIALS[name], eye)
    covered = (front.passes["Depth"] < 1e9) & (front.passes["IndexOB"] == 0)
    assert covered.mean() > 0.5
    lb, lf = luminance(back.passes["Combined"]), luminance(front.passes["Combined"])
    print(f"{name}: mean back/front {lb[covered].mean() / lf[covered].mean():.4f}, near-black "
          f"{(lb[covered] < NEAR_BLACK * np.median(lf[covered])).mean():.4f}")
    if name != "glass":
        assert lb[covered].mean() == pytest.approx(lf[covered].mean(), rel=0.01)
    assert (lb[covered] < NEAR_BLACK * np.median(lf[covered])).mean() <= MAX_NEAR_BLACK
    np.testing.assert_allclose(back.passes["Normal"], front.passes["Normal"], atol=1e-5)


def test_closed_clouds_keep_their_one_sided_rules():
    """A closed cloud is not two-sided: its back hits are the method's (wrong hits, exits),
    and the Normal pass keeps the true normal -- seen from outside, and from inside, where
    every hit is a back hit (the camera-inside rule)."""
    c, n, r = sphere_cloud(6000, 1.0, seed=1)
    outside = Camera.look_at((0.3, -4.0, 1.2), (0, 0, 0), fov_y=40.0)
    inside = Camera.look_at((0.1, 0.0, 0.05), (0.0, 1.0, 0.0), fov_y=60.0)
    lamp = [Light("POINT", power=100.0, position=(0.0, -3.0, 2.0))]
    for camera in (outside, inside):
        cloud = SplatCloud(c, n, r, closed=True)
        frame = RenderScene([Instance(cloud)], lights=lamp).render(camera, 64, 48, RenderSettings(samples=1),
                                                                   method=FULL, passes=("Normal", "Depth"))
        o, d = camera.rays(64, 48)
        surf = cloud.trace_surface(o, d, FULL, inside=camera is inside)
        hit = (surf.id >= 0).reshape(48, 64)
        assert hit.mean() > 0.2 and np.array_equal(hit, frame.passes["Depth"] < 1e9)
        np.testing.assert_allclose(frame.passes["Normal"][hit], surf.normal.reshape(48, 64, 3)[hit], atol=1e-6)
