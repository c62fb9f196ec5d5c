"""Panoramic cameras (issue 25): the core's ray directions (Camera.rays: the core's
Camera::ray) against the angles each projection promises, computed here from the pixel
centres the other way round (from the direction back to longitude/latitude or to the angle
off the view axis and its azimuth), and the passes a panorama writes: black with alpha 0
where the projection sees nothing, and the Depth pass as the distance from the camera
(Cycles' camera_z_depth). Float32 rays: angles agree to ANGLE_ATOL (1e-5 rad, float's
precision on a unit vector is about 1e-7; the atan2/asin round trip keeps it)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from splat_tracer.render.camera import Camera, Panorama
from splat_tracer.render.method import Method
from splat_tracer.render.scene import Instance, Mesh, RenderScene
from splat_tracer.render.shading import Material, RenderSettings, World
from splat_tracer.render.splats import SplatCloud

from geometry import random_sphere

ANGLE_ATOL = 1e-5
W, H = 24, 12


def _centres(width, height):
    """(u, v) of the pixel centres in [0, 1], v upwards, row-major from the top row."""
    j, i = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    return (j / width).ravel(), (1.0 - i / height).ravel()


def _rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def _camera_space(camera, d):
    """Directions back in camera space (the camera's matrix undone)."""
    return d.astype(np.float64) @ camera.local_from_camera[:3, :3]  # rows times R = R^T d: R orthonormal


def _pano(panorama, frustum=(0.0, 1.0, 0.0, 1.0), rotation=np.eye(3), position=(1.0, -2.0, 0.5)):
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = rotation, position
    return Camera(m, frustum, (0.01, 100.0), panorama=panorama)


@pytest.mark.parametrize("lon, lat, rotation", [
    ((-math.pi, math.pi), (-math.pi / 2, math.pi / 2), np.eye(3)),
    ((-0.5, 2.0), (-0.3, 1.1), _rotation((1, 2, 3), 0.7)),
])
def test_equirectangular_pixel_centres_map_to_their_longitude_and_latitude(lon, lat, rotation):
    cam = _pano(Panorama("EQUIRECTANGULAR", (*lon, *lat)), rotation=rotation)
    origins, d = cam.rays(W, H)
    c = _camera_space(cam, d)
    u, v = _centres(W, H)
    # Longitude: from the view axis (-Z) towards the camera's right (+X); latitude: up (+Y).
    np.testing.assert_allclose(np.arctan2(c[:, 0], -c[:, 2]), lon[0] + (lon[1] - lon[0]) * u, atol=ANGLE_ATOL)
    np.testing.assert_allclose(np.arcsin(np.clip(c[:, 1], -1, 1)), lat[0] + (lat[1] - lat[0]) * v, atol=ANGLE_ATOL)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-6)
    # Every ray leaves the camera's centre, clip start along itself.
    np.testing.assert_allclose(origins, cam.position + 0.01 * d, atol=1e-6)


def test_equirectangular_landmarks():
    """The full sphere: the middle column looks ahead, a quarter to the right looks right,
    the top row looks (nearly) up."""
    cam = _pano(Panorama("EQUIRECTANGULAR", (-math.pi, math.pi, -math.pi / 2, math.pi / 2)))
    _, d = cam.rays(4, 2)
    c = _camera_space(cam, d).reshape(2, 4, 3)
    # Columns 0..3 at longitudes -135, -45, 45, 135 degrees; rows at latitudes +45, -45.
    s = math.sqrt(0.5)
    np.testing.assert_allclose(c[0, 2], (0.5, s, -0.5), atol=1e-6)   # ahead-right, up
    np.testing.assert_allclose(c[1, 1], (-0.5, -s, -0.5), atol=1e-6)  # ahead-left, down
    np.testing.assert_allclose(c[0, 3], (0.5, s, 0.5), atol=1e-6)    # behind-right, up


def _angle_and_azimuth(c):
    """Angle off the view axis (-Z) and azimuth (from +X towards +Y) of camera-space directions."""
    return np.arccos(np.clip(-c[:, 2], -1, 1)), np.arctan2(c[:, 1], c[:, 0])


@pytest.mark.parametrize("fov", [math.pi, math.radians(120), math.radians(250)])
def test_fisheye_equidistant_angle_is_proportional_to_the_radius(fov):
    cam = _pano(Panorama("FISHEYE_EQUIDISTANT", (fov,)), rotation=_rotation((0, 1, 1), 1.2))
    _, d = cam.rays(W, W)
    u, v = _centres(W, W)
    x, y = 2 * u - 1, 2 * v - 1
    r = np.hypot(x, y)
    inside = r <= 1
    assert 0 < inside.sum() < W * W
    assert np.all(d[~inside] == 0), "outside the circle: no ray"
    theta, phi = _angle_and_azimuth(_camera_space(cam, d[inside]))
    np.testing.assert_allclose(theta, r[inside] * fov / 2, atol=ANGLE_ATOL)
    np.testing.assert_allclose(np.cos(phi), x[inside] / r[inside], atol=ANGLE_ATOL)
    np.testing.assert_allclose(np.sin(phi), y[inside] / r[inside], atol=ANGLE_ATOL)


def test_fisheye_equisolid_maps_the_sensor_radius_to_2_f_sin_half_angle():
    lens, fov, sensor = 10.5, math.pi, (36.0, 18.0)
    cam = _pano(Panorama("FISHEYE_EQUISOLID", (lens, fov, *sensor)))
    _, d = cam.rays(W, H)
    u, v = _centres(W, H)
    x, y = (u - 0.5) * sensor[0], (v - 0.5) * sensor[1]
    r = np.hypot(x, y)
    inside = r <= 2 * lens * math.sin(fov / 4)
    assert 0 < inside.sum() < W * H and np.all(d[~inside] == 0)
    theta, phi = _angle_and_azimuth(_camera_space(cam, d[inside]))
    np.testing.assert_allclose(2 * lens * np.sin(theta / 2), r[inside], rtol=1e-5)
    np.testing.assert_allclose(np.cos(phi), x[inside] / r[inside], atol=ANGLE_ATOL)


def test_equisolid_sensor_fit_is_cycles():
    assert Panorama.equisolid_sensor(36, 24, "AUTO", 200, 100) == (36, 18)
    assert Panorama.equisolid_sensor(36, 24, "AUTO", 100, 200) == (18, 36)  # AUTO fits the width to the longer side
    assert Panorama.equisolid_sensor(36, 24, "VERTICAL", 200, 100) == (48, 24)
    assert Panorama.equisolid_sensor(36, 24, "HORIZONTAL", 100, 200) == (36, 72)


def test_mirrorball_centre_looks_ahead_and_angle_is_twice_the_normals():
    """A mirror ball reflects a ray hitting it at normal angle b by 2 b: the disc's centre
    sees straight ahead, radius r (sin b) sees 2 asin(r) off the view axis, its rim behind."""
    cam = _pano(Panorama("MIRRORBALL"), rotation=_rotation((1, 0, 0), 0.4))
    _, d = cam.rays(W, W)
    u, v = _centres(W, W)
    x, y = 2 * u - 1, 2 * v - 1
    r = np.hypot(x, y)
    inside = r <= 1
    assert np.all(d[~inside] == 0)
    theta, phi = _angle_and_azimuth(_camera_space(cam, d[inside]))
    np.testing.assert_allclose(theta, 2 * np.arcsin(r[inside]), atol=1e-4)  # arccos near pi: 1e-4
    np.testing.assert_allclose(np.cos(phi), x[inside] / r[inside], atol=ANGLE_ATOL)


def test_shift_moves_the_panorama_window():
    """The frustum of a panorama is its (u, v) window: shifted by a quarter, the image's
    middle column looks a quarter turn to the right."""
    full = (-math.pi, math.pi, -math.pi / 2, math.pi / 2)
    cam = _pano(Panorama("EQUIRECTANGULAR", full), frustum=(0.25, 1.25, 0.0, 1.0))
    _, d = cam.rays(1, 1)
    np.testing.assert_allclose(_camera_space(cam, d)[0], (1.0, 0.0, 0.0), atol=1e-6)


def test_panorama_refuses_bad_parameters_by_name():
    with pytest.raises(ValueError, match="FISHEYE_EQUIDISTANT"):
        Panorama("FISHEYE_EQUIDISTANT", ())
    with pytest.raises(ValueError, match="field of view"):
        Panorama("FISHEYE_EQUIDISTANT", (0.0,))
    with pytest.raises(ValueError, match="panorama kind"):
        Panorama("CENTRAL_CYLINDRICAL", ())
    with pytest.raises(ValueError, match="orthographic or panoramic"):
        Camera(np.eye(4), (0, 1, 0, 1), (0.1, 10), True, panorama=Panorama("MIRRORBALL"))


def _shell(radius=3.0, n=20000):
    p, nrm = random_sphere(n, radius, seed=2)
    return SplatCloud(p.astype(np.float32), nrm.astype(np.float32), np.full(n, 0.12, np.float32))


def test_fisheye_outside_the_circle_is_black_and_transparent_and_depth_is_the_distance():
    """Inside a shell of radius 3 around the camera: every seen pixel's Depth is 3 (planar
    depth would fall to 0 towards 90 degrees off axis); outside the circle, (0, 0, 0, 0)
    whatever the background."""
    cam = _pano(Panorama("FISHEYE_EQUIDISTANT", (math.radians(200),)), position=(0.0, 0.0, 0.0))
    res = _shell().render(cam, 32, 32, background=(0.5, 0.5, 0.5, 1.0))
    u, v = _centres(32, 32)
    inside = (np.hypot(2 * u - 1, 2 * v - 1) <= 1).reshape(32, 32)
    assert np.all(res.rgba[~inside] == 0)
    seen = inside & (res.rgba[..., 3] > 0)
    assert seen.sum() > 0.95 * inside.sum()
    np.testing.assert_allclose(res.depth[seen], 3.0, atol=0.02)  # splats sit on the sphere to ~their radius^2/2r


def test_path_traced_panorama_depth_and_outside_pixels():
    """The same through RenderScene (the integrator): distance depth, and outside the
    circle (0, 0, 0, 0) under a grey world while every pixel inside is opaque."""
    z = 2.0
    # A cube of six emitting faces at distance 2 around the camera.
    v = np.array([[x, y, zz] for x in (-z, z) for y in (-z, z) for zz in (-z, z)], np.float32)
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1), (2, 3, 7), (2, 7, 6),
             (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    mesh = Mesh(v, np.array(faces, np.int32))
    scene = RenderScene([Instance(mesh, materials=(Material(base_colour=(0, 0, 0), emission=(1, 1, 1)),))], [],
                        World(colour=(0.3, 0.3, 0.3)))
    cam = _pano(Panorama("FISHEYE_EQUIDISTANT", (math.radians(180),)), position=(0.0, 0.0, 0.0))
    # The pixel filter shrunk to (almost) nothing: every sample at its pixel's centre.
    settings = RenderSettings(samples=4, pixel_filter="BOX", filter_width=0.01, max_bounces=0)
    out = scene.render(cam, 16, 16, settings, Method(), passes=("Combined", "Depth"))
    u, vv = _centres(16, 16)
    inside = (np.hypot(2 * u - 1, 2 * vv - 1) <= 1).reshape(16, 16)
    combined = out.passes["Combined"]
    assert np.all(combined[~inside] == 0)
    assert np.all(combined[inside][:, 3] == 1) and np.all(combined[inside][:, :3] >= 1)
    # Depth: the distance to the cube's wall along each ray, 2 / max |direction component|.
    _, d = cam.rays(16, 16)
    d = d.reshape(16, 16, 3)
    expected = z / np.abs(d[inside]).max(axis=1)
    np.testing.assert_allclose(out.passes["Depth"][inside], expected, rtol=1e-4)
